// Inputs found by fuzzing checkpoints (fuzz/fuzz_checkpoint.cpp; docs/reliability.md), failing before their fix
// (under UBSan: a float cast to int out of range), now a one-line hgs::Error naming the file.
#include <gtest/gtest.h>

#include <cstring>

#include "core/error.h"
#include "core/fs.h"
#include "expect_error.h"
#include "hybrid/config.h"
#include "hybrid/register.h"
#include "scene/scene.h"
#include "test_util.h"
#include "train/registry.h"

using namespace hgs;
namespace fs = std::filesystem;

namespace {
// The fuzz harnesses' tiny scene (fuzz/util.cpp), on which the inputs were found.
void write_tiny_scene(const fs::path& out) {
  const auto r = test::run_hgs("synth --world simple --out " + out.string() +
                               " --views 4 --width 32 --height 24 --objects 3 --points 200 --feature-dim 8 --noise none"
                               " --supersample 1 --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
}
}  // namespace

// fuzz_checkpoint: a densification count of 5.3e22 in stats/count of a hybrid checkpoint was cast to int.
TEST(FuzzRegressions, CheckpointCountOutOfRange) {
  test::TempDir t;
  ASSERT_NO_FATAL_FAILURE(write_tiny_scene(t / "tiny"));
  const Scene scene = load_scene(t / "tiny");
  train::TrainConfig base;
  base.sh_degree = 0;
  train::TrainConfig cfg = base.scaled_to(20);
  cfg.method = "hybrid";
  hybrid::register_method();
  auto trainer =
      train::make_trainer(scene, scene.train_indices(), cfg, "hybrid", hybrid::HybridConfig{}.to_json(), false);
  const fs::path file =
      fs::path(HGS_SOURCE_DIR) / "tests" / "data" / "fuzz_findings" / "checkpoint_count_out_of_range.ckpt";
  EXPECT_FILE_ERROR(trainer->load_checkpoint(file), file, "corrupt densification statistics");
}

// fuzz_checkpoint: a header length of ~3 GB (a file of a few KB) was allocated before reading; the length is now
// checked against the file's size.
TEST(FuzzRegressions, CheckpointHeaderLongerThanTheFile) {
  test::TempDir t;
  ASSERT_NO_FATAL_FAILURE(write_tiny_scene(t / "tiny"));
  auto r = test::run_hgs("train " + (t / "tiny").string() + " --out " + (t / "m").string() +
                         " --method rgb --iters 4 --save-every 4 --sh-degree 0 --threads 1 --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const fs::path good = t / "m" / "checkpoints" / "iter_4.ckpt";
  std::vector<uint8_t> b = read_file_bytes(good);
  ASSERT_GT(b.size(), 16u);
  const uint64_t len = uint64_t(3) << 30;  // bytes 8..15: the header's length
  std::memcpy(b.data() + 8, &len, 8);
  const fs::path bad = t / "bad.ckpt";
  atomic_write_bytes(bad, b.data(), b.size());
  const Scene scene = load_scene(t / "tiny");
  train::TrainConfig base;
  base.sh_degree = 0;
  train::TrainConfig cfg = base.scaled_to(4);
  auto trainer = train::make_trainer(scene, scene.train_indices(), cfg, "rgb", nlohmann::json(), false);
  EXPECT_FILE_ERROR(trainer->load_checkpoint(bad), bad, "truncated checkpoint header");
  EXPECT_NO_THROW(trainer->load_checkpoint(good));
}
