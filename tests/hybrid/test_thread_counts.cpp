// The trained model does not depend on the thread count: `hgs train` of the full method on 1 and on 3 threads, and
// a run resumed on 2 threads from a checkpoint written on 3, write the same PLY byte for byte (docs/scaling.md promises
// it; SCL's pooled predictions and the fusion backward's view gradients were summed in per-thread partials added in
// thread order, and gave other bits on another count).
#include <gtest/gtest.h>

#include "core/fs.h"
#include "test_util.h"

using namespace hgs;

TEST(ThreadCounts, HybridTrainingWritesTheSameModelOnOneAndThreeThreads) {
  test::TempDir t;
  const std::string s = (t / "s").string();
  auto r = test::run_hgs("synth --out " + s +
                         " --views 16 --width 128 --height 96 --objects 4 --points 3000 --noise low"
                         " --feature-dim 32 --supersample 1 --seed 5 --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  // 300 images: densification (its schedule scaled to the run: 3000 -> about 5100 Gaussians) and the observation
  // table's rebuilds included.
  for (const char* threads : {"1", "3"}) {
    r = test::run_hgs("train " + s + " --out " + (t / "m").string() + threads +
                      " --iters 300 --sh-degree 1 --threads " + threads + " --save-every 150 --quiet");
    ASSERT_EQ(r.exit_code, 0) << r.err;
  }
  const std::string one = read_file_text(t / "m1" / "point_cloud.ply"),
                    three = read_file_text(t / "m3" / "point_cloud.ply");
  ASSERT_GT(one.size(), 1000u);
  EXPECT_TRUE(one == three) << "the models trained on 1 and on 3 threads differ";
  // A run checkpointed on 3 threads and resumed on 2 ends where the uninterrupted runs end.
  r = test::run_hgs("train " + s + " --out " + (t / "r").string() + " --iters 300 --sh-degree 1 --threads 2 --resume " +
                    (t / "m3" / "checkpoints" / "iter_150.ckpt").string() + " --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(read_file_text(t / "r" / "point_cloud.ply") == one) << "resumed on 2 threads, the model differs";
}
