// Inputs found by fuzzing checkpoints (fuzz/fuzz_checkpoint.cpp; docs/reliability.md), failing before their fix
// (under UBSan: a float cast to int out of range), now a one-line hgs::Error naming the file.
#include <gtest/gtest.h>

#include "core/error.h"
#include "expect_error.h"
#include "scene/scene.h"
#include "test_util.h"
#include "hybrid/config.h"
#include "hybrid/register.h"
#include "train/registry.h"

using namespace hgs;
namespace fs = std::filesystem;

// fuzz_checkpoint: a densification count of 5.3e22 in stats/count of a hybrid checkpoint was cast to int.
TEST(FuzzRegressions, CheckpointCountOutOfRange) {
  test::TempDir t;
  // The fuzz harnesses' tiny scene (fuzz/util.cpp), on which the input was found.
  auto r = test::run_hgs("synth --out " + (t / "tiny").string() +
                         " --views 4 --width 32 --height 24 --objects 3 --points 200 --feature-dim 8 --noise none"
                         " --supersample 1 --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const Scene scene = load_scene(t / "tiny");
  train::TrainConfig base;
  base.sh_degree = 0;
  train::TrainConfig cfg = base.scaled_to(20);
  cfg.method = "hybrid";
  hybrid::register_method();
  auto trainer = train::make_trainer(scene, scene.train_indices(), cfg, "hybrid", hybrid::HybridConfig{}.to_json(), false);
  const fs::path file = fs::path(HGS_SOURCE_DIR) / "tests" / "data" / "fuzz_findings" / "checkpoint_count_out_of_range.ckpt";
  EXPECT_FILE_ERROR(trainer->load_checkpoint(file), file, "corrupt densification statistics");
}
