// mpirun -np 2 hgs train against one process with --batch 2 (bit for bit, both methods), resume with another
// number of ranks, and a rank that dies. Skips when mpirun is missing (scripts/setup installs OpenMPI) or this
// hgs was built without MPI.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <string>

#include <nlohmann/json.hpp>

#include "core/fs.h"
#include "test_util.h"

namespace hgs {
namespace {
namespace fs = std::filesystem;

bool have_mpirun() { return std::system("command -v mpirun >/dev/null 2>&1") == 0; }

// A shell command line running `args` on `ranks` ranks on this machine.
std::string mpirun(int ranks, const std::string& args, const std::string& env = "") {
  return "mpirun -np " + std::to_string(ranks) + " --oversubscribe " + env + " " + HGS_BINARY + " " + args;
}

test::RunResult run(const std::string& cmd) {
  test::TempDir t;
  const int st = std::system((cmd + " >" + (t / "out").string() + " 2>" + (t / "err").string()).c_str());
  return {WIFEXITED(st) ? WEXITSTATUS(st) : -1, read_file_text(t / "out"), read_file_text(t / "err")};
}

bool same_bytes(const fs::path& a, const fs::path& b) { return read_file_text(a) == read_file_text(b); }

class MpiTrain : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    setenv("OMP_WAIT_POLICY", "passive", 0);
    // Containers run as root; OpenMPI refuses that unless told it is meant.
    setenv("OMPI_ALLOW_RUN_AS_ROOT", "1", 0);
    setenv("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1", 0);
    if (!have_mpirun()) return;
    dir_ = new test::TempDir;
    auto r = test::run_hgs("synth --world simple --out " + (dir_->path / "scene").string() +
                           " --seed 4 --views 12 --width 64 --height 48 --points 1500 --feature-dim 8 --quiet");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    auto p = run(mpirun(2, "train " + scene() + " --out " + (dir_->path / "probe").string() + " --iters 2 --quiet"));
    mpi_built_ = p.err.find("built without MPI") == std::string::npos;
  }
  static void TearDownTestSuite() { delete dir_; }
  void SetUp() override {
    if (!have_mpirun()) GTEST_SKIP() << "mpirun not found (scripts/setup installs OpenMPI): MPI training not tested";
    if (!mpi_built_) GTEST_SKIP() << "this hgs was built without MPI (libopenmpi-dev missing at configure time)";
  }
  static std::string scene() { return (dir_->path / "scene").string(); }
  static test::TempDir* dir_;
  static bool mpi_built_;
};
test::TempDir* MpiTrain::dir_ = nullptr;
bool MpiTrain::mpi_built_ = false;

TEST_F(MpiTrain, TwoRanksEqualOneProcessWithBatchTwoBitForBit) {
  // 200 images = 100 steps of 2: densification at 100, the hybrid table rebuilt, SCL anchors every step. The one
  // process runs 2 threads, each rank 1: the model does not depend on the thread count either.
  for (std::string method : {"rgb", "hybrid"}) {
    test::TempDir out;
    const std::string common = "train " + scene() + " --method " + method + " --iters 200 --seed 3 --quiet";
    auto one = test::run_hgs(common + " --threads 2 --batch 2 --out " + (out / "one").string());
    ASSERT_EQ(one.exit_code, 0) << one.err;
    auto two = run(mpirun(2, common + " --threads 1 --out " + (out / "two").string()));
    ASSERT_EQ(two.exit_code, 0) << two.out << two.err;
    EXPECT_TRUE(same_bytes(out / "one" / "point_cloud.ply", out / "two" / "point_cloud.ply")) << method;
    auto stats = nlohmann::json::parse(read_file_text(out / "two" / "train_stats.json"));
    EXPECT_EQ(stats["ranks"], 2);
    EXPECT_EQ(stats["views_per_step"], 2);
    EXPECT_GT(stats["comm_bytes_per_step"].get<double>(), 0);
    // A batch is not one view: the single-view run differs (the test would pass vacuously otherwise).
    auto single = test::run_hgs(common + " --threads 1 --out " + (out / "single").string());
    ASSERT_EQ(single.exit_code, 0) << single.err;
    EXPECT_FALSE(same_bytes(out / "one" / "point_cloud.ply", out / "single" / "point_cloud.ply")) << method;
  }
}

TEST_F(MpiTrain, ResumesWithAnotherNumberOfRanks) {
  test::TempDir out;
  const std::string common = "train " + scene() + " --method hybrid --iters 200 --threads 1 --seed 5 --quiet";
  auto full = run(mpirun(2, common + " --save-every 100 --out " + (out / "full").string()));
  ASSERT_EQ(full.exit_code, 0) << full.err;
  // The checkpoint of 2 ranks, continued by one process with the same global batch: the same model.
  fs::create_directories(out / "resumed");
  auto res = test::run_hgs(common + " --batch 2 --out " + (out / "resumed").string() + " --resume " +
                           (out / "full" / "checkpoints" / "iter_100.ckpt").string());
  ASSERT_EQ(res.exit_code, 0) << res.err;
  EXPECT_TRUE(same_bytes(out / "full" / "point_cloud.ply", out / "resumed" / "point_cloud.ply"));
  // And by one process with one view per step (another global batch): it runs to the end.
  auto one = test::run_hgs(common + " --out " + (out / "one").string() + " --resume " +
                           (out / "full" / "checkpoints" / "iter_100.ckpt").string());
  ASSERT_EQ(one.exit_code, 0) << one.err;
  EXPECT_TRUE(fs::exists(out / "one" / "point_cloud.ply"));
}

TEST_F(MpiTrain, DeadRankEndsTheJobAndTheLastCheckpointResumes) {
  test::TempDir out;
  const std::string common = "train " + scene() + " --method rgb --iters 200 --threads 1 --seed 6 --quiet";
  // Rank 1 dies (SIGKILL) after 150 images; rank 0 waits in the next gradient exchange until mpirun ends it.
  auto r = run("timeout 300 " +
               mpirun(2, common + " --save-every 50 --out " + (out / "m").string(), "-x HGS_TEST_KILL=1:150"));
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.exit_code, 124) << "the job hung instead of ending";
  EXPECT_NE(r.err.find("signal 9"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out / "m" / "point_cloud.ply"));
  ASSERT_TRUE(fs::exists(out / "m" / "checkpoints" / "iter_100.ckpt"));
  for (const auto& e : fs::directory_iterator(out / "m" / "checkpoints"))
    EXPECT_EQ(e.path().extension(), ".ckpt") << e.path();
  // The newest checkpoint resumes (on one process, the same global batch).
  fs::path newest = out / "m" / "checkpoints" /
                    (fs::exists(out / "m" / "checkpoints" / "iter_150.ckpt") ? "iter_150.ckpt" : "iter_100.ckpt");
  auto res = test::run_hgs(common + " --batch 2 --out " + (out / "m").string() + " --resume " + newest.string());
  ASSERT_EQ(res.exit_code, 0) << res.err;
  EXPECT_TRUE(fs::exists(out / "m" / "point_cloud.ply"));
}

TEST(BatchCli, StepSizesThatDoNotDivideAreOneLineErrors) {
  test::TempDir d;
  auto s = test::run_hgs("synth --world simple --out " + (d / "s").string() +
                         " --views 6 --width 32 --height 24 --points 300 --feature-dim 4 --quiet");
  ASSERT_EQ(s.exit_code, 0) << s.err;
  auto r =
      test::run_hgs("train " + (d / "s").string() + " --method rgb --iters 101 --batch 2 --out " + (d / "m").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("not a multiple of the 2 views of a step"), std::string::npos) << r.err;
  r = test::run_hgs("train " + (d / "s").string() + " --method rgb --iters 100 --batch 64 --out " + (d / "m").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("more than the"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(d / "m" / "point_cloud.ply"));
}

}  // namespace
}  // namespace hgs
