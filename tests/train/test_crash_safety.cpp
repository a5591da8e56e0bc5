// Crash-safe outputs (docs/reliability.md): `hgs train --save-every N` and `hgs eval` killed with SIGKILL at
// seeded random moments leave only complete files (old or new: PLYs load, checkpoints are whole, JSON parses,
// PNGs decode, no temporary files); --resume from the last checkpoint then ends with the same PLY bytes as an
// uninterrupted run (fixed seed and threads); a file size limit (RLIMIT_FSIZE, SIGXFSZ ignored: the write fails
// with EFBIG as on a full disk) or a read-only output folder gives a one-line error and no partial file.
// Numerical faults: a NaN injected into a loss or gradient (HGS_INJECT_NAN) stops training at that iteration
// naming the group, and the last checkpoint stays byte-identical. Tiny synthetic scene (12 views at 48x36).
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <linux/capability.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/stat.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <regex>

#include <nlohmann/json.hpp>

#include "core/fs.h"
#include "crash_util.h"
#include "test_util.h"

namespace hgs {
namespace {
namespace fs = std::filesystem;

constexpr int kIters = 40, kSaveEvery = 8;

class CrashSafety : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    setenv("OMP_WAIT_POLICY", "passive", 0);
    dir_ = new test::TempDir;
    auto r = test::run_hgs("synth --world simple --out " + (dir_->path / "scene").string() +
                           " --seed 2 --views 12 --width 48 --height 36 --points 400 --noise none --feature-dim 4"
                           " --supersample 1 --quiet");
    ASSERT_EQ(r.exit_code, 0) << r.err;
  }
  static void TearDownTestSuite() { delete dir_; }
  static std::string scene() { return (dir_->path / "scene").string(); }
  static std::vector<std::string> train_args(const fs::path& out, int iters = kIters) {
    return {"train",        scene(),
            "--out",        out.string(),
            "--iters",      std::to_string(iters),
            "--save-every", std::to_string(kSaveEvery),
            "--threads",    "2",
            "--seed",       "5",
            "--quiet"};
  }
  // Runs to the end; returns the exit status (stderr in *err).
  static int run(const std::vector<std::string>& args, const fs::path& logs, std::string* err = nullptr,
                 const std::function<void()>& in_child = {}) {
    fs::create_directories(logs);
    test::Child c = test::spawn_hgs(args, logs, in_child);
    const int st = test::wait_child(c);
    if (err) *err = read_file_text(c.err_file);
    return st;
  }
  static test::TempDir* dir_;
};
test::TempDir* CrashSafety::dir_ = nullptr;

std::string join(const std::vector<std::string>& v) {
  std::string s;
  for (auto& x : v) s += x + "\n";
  return s;
}

int newest_checkpoint(const fs::path& dir) {
  int best = 0;
  if (!fs::is_directory(dir)) return 0;
  for (auto& e : fs::directory_iterator(dir)) {
    std::smatch m;
    const std::string n = e.path().filename().string();
    if (std::regex_match(n, m, std::regex(R"(iter_(\d+)\.ckpt)"))) best = std::max(best, std::stoi(m[1]));
  }
  return best;
}

TEST_F(CrashSafety, KilledTrainingLeavesCompleteFilesAndResumesBitExact) {
  test::TempDir t;
  // Uninterrupted reference run (its wall time sets the range of the kill moments).
  const auto t0 = std::chrono::steady_clock::now();
  std::string err;
  ASSERT_EQ(run(train_args(t / "ref"), t / "ref_logs", &err), 0) << err;
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  const std::vector<uint8_t> ref = read_file_bytes(t / "ref" / "point_cloud.ply");
  EXPECT_TRUE(test::incomplete_outputs(t / "ref").empty()) << join(test::incomplete_outputs(t / "ref"));

  // Killed runs into one folder (later runs replace the files of earlier ones): fresh runs and runs resumed
  // from the newest checkpoint the earlier ones left, alternately.
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> when(0.0, ms);
  const fs::path out = t / "out";
  int killed = 0, finished = 0;
  for (int round = 0; round < 8; ++round) {
    std::vector<std::string> args = train_args(out);
    const int last = newest_checkpoint(out / "checkpoints");
    if (round % 2 == 1 && last > 0 && last < kIters) {
      args.push_back("--resume");
      args.push_back((out / "checkpoints" / fmt::format("iter_{}.ckpt", last)).string());
    }
    const fs::path logs = t / fmt::format("logs{}", round);
    fs::create_directories(logs);
    const double at = when(rng);
    const int st = test::kill_after(test::spawn_hgs(args, logs), at);
    if (st == -SIGKILL) ++killed;
    else if (st == 0) ++finished;
    else ADD_FAILURE() << "round " << round << ": exit " << st << ": " << read_file_text(logs / "stderr.txt");
    const auto bad = test::incomplete_outputs(out);
    EXPECT_TRUE(bad.empty()) << "round " << round << " (killed at " << at << " ms):\n" << join(bad);
  }
  EXPECT_GE(killed, 4) << "the kill moments should mostly fall inside the runs (reference run: " << ms << " ms)";
  // Resume from the newest checkpoint before the end that the killed runs left (any run's: all are complete
  // and all of one trajectory), then compare with the uninterrupted run.
  int last = 0;
  for (int k = kSaveEvery; k < kIters; k += kSaveEvery)
    if (fs::exists(out / "checkpoints" / fmt::format("iter_{}.ckpt", k))) last = k;
  std::vector<std::string> args = train_args(out);
  if (last > 0)
    args.insert(args.end(), {"--resume", (out / "checkpoints" / fmt::format("iter_{}.ckpt", last)).string()});
  ASSERT_EQ(run(args, t / "final_logs", &err), 0) << err;
  std::printf("%d of 8 runs killed, final run resumed from iteration %d\n", killed, last);
  const std::vector<uint8_t> got = read_file_bytes(out / "point_cloud.ply");
  EXPECT_TRUE(got == ref) << "resumed model differs from the uninterrupted run (" << got.size() << " vs " << ref.size()
                          << " bytes; " << killed << " kills, " << finished << " finished)";
  EXPECT_TRUE(read_file_bytes(out / "checkpoints" / fmt::format("iter_{}.ckpt", kIters)) ==
              read_file_bytes(t / "ref" / "checkpoints" / fmt::format("iter_{}.ckpt", kIters)))
      << "final checkpoints differ";
}

TEST_F(CrashSafety, KilledEvalLeavesCompleteFiles) {
  test::TempDir t;
  std::string err;
  ASSERT_EQ(run(train_args(t / "model", 20), t / "train_logs", &err), 0) << err;
  const std::vector<std::string> args = {"eval",
                                         scene(),
                                         (t / "model").string(),
                                         "--protocol",
                                         "instances",
                                         "--out",
                                         (t / "ev" / "report.json").string(),
                                         "--threads",
                                         "2",
                                         "--quiet"};
  const auto t0 = std::chrono::steady_clock::now();
  ASSERT_EQ(run(args, t / "ref_logs", &err), 0) << err;
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  const nlohmann::json report = nlohmann::json::parse(read_file_text(t / "ev" / "report.json"));
  ASSERT_GE(report["reports"].size(), 1u);
  ASSERT_TRUE(fs::is_directory(t / "ev" / "overlays"));
  std::mt19937 rng(23);
  std::uniform_real_distribution<double> when(0.0, ms);
  int killed = 0;
  for (int round = 0; round < 6; ++round) {
    const fs::path logs = t / fmt::format("logs{}", round);
    fs::create_directories(logs);
    const double at = when(rng);
    const int st = test::kill_after(test::spawn_hgs(args, logs), at);
    killed += st == -SIGKILL;
    EXPECT_TRUE(st == 0 || st == -SIGKILL) << "exit " << st << ": " << read_file_text(logs / "stderr.txt");
    const auto bad = test::incomplete_outputs(t / "ev");
    EXPECT_TRUE(bad.empty()) << "round " << round << " (killed at " << at << " ms):\n" << join(bad);
    // Old or new: the same reports (timings aside).
    const auto j = nlohmann::json::parse(read_file_text(t / "ev" / "report.json"), nullptr, false);
    ASSERT_FALSE(j.is_discarded());
    EXPECT_EQ(j["reports"].size(), report["reports"].size());
  }
  EXPECT_GE(killed, 2);
}

// In the child: writes beyond `bytes` fail with EFBIG (as on a full disk) instead of killing it.
std::function<void()> file_size_limit(rlim_t bytes) {
  return [bytes] {
    ::signal(SIGXFSZ, SIG_IGN);
    rlimit l{bytes, bytes};
    ::setrlimit(RLIMIT_FSIZE, &l);
  };
}

TEST_F(CrashSafety, FileSizeLimitGivesOneLineErrorAndNoPartialFile) {
  test::TempDir t;
  // The checkpoint (tens of kB) and the PLY exceed 20 kB; config.json does not.
  std::string err;
  const int st = run(train_args(t / "out"), t / "logs", &err, file_size_limit(20000));
  EXPECT_EQ(st, 1) << err;
  EXPECT_EQ(std::count(err.begin(), err.end(), '\n'), 1) << err;
  EXPECT_NE(err.find("iter_8.ckpt: write failed"), std::string::npos) << err;
  EXPECT_NE(err.find("File too large"), std::string::npos) << err;
  EXPECT_FALSE(fs::exists(t / "out" / "checkpoints" / "iter_8.ckpt"));
  EXPECT_FALSE(fs::exists(t / "out" / "point_cloud.ply"));
  EXPECT_TRUE(test::incomplete_outputs(t / "out").empty()) << join(test::incomplete_outputs(t / "out"));

  // eval: report.json is small; the overlay PNGs are not all below 300 bytes.
  ASSERT_EQ(run(train_args(t / "model", 8), t / "train_logs", &err), 0) << err;
  const int est = run({"eval", scene(), (t / "model").string(), "--protocol", "instances", "--out",
                       (t / "ev" / "report.json").string(), "--threads", "2", "--quiet"},
                      t / "eval_logs", &err, file_size_limit(300));
  EXPECT_EQ(est, 1) << err;
  EXPECT_EQ(std::count(err.begin(), err.end(), '\n'), 1) << err;
  EXPECT_NE(err.find("File too large"), std::string::npos) << err;
  EXPECT_TRUE(test::incomplete_outputs(t / "ev").empty()) << join(test::incomplete_outputs(t / "ev"));
  EXPECT_FALSE(fs::exists(t / "ev" / "report.json"));
}

TEST_F(CrashSafety, ReadOnlyOutputGivesOneLineErrorAndNoFile) {
  test::TempDir t;
  fs::create_directories(t / "ro");
  fs::permissions(t / "ro", fs::perms::owner_read | fs::perms::owner_exec | fs::perms::group_read |
                                fs::perms::group_exec | fs::perms::others_read | fs::perms::others_exec);
  // As root the permission bits do not bind: the child drops the capabilities that bypass them.
  auto no_override = [] {
    if (::geteuid() == 0)
      for (int cap : {CAP_DAC_OVERRIDE, CAP_DAC_READ_SEARCH, CAP_FOWNER})
        if (::prctl(PR_CAPBSET_DROP, cap, 0, 0, 0) != 0) ::_exit(125);
  };
  std::string err;
  int st = run(train_args(t / "ro"), t / "logs", &err, no_override);
  if (st == 125) GTEST_SKIP() << "cannot drop CAP_DAC_OVERRIDE here";
  EXPECT_EQ(st, 1) << err;
  EXPECT_EQ(std::count(err.begin(), err.end(), '\n'), 1) << err;
  EXPECT_NE(err.find("config.json: cannot write (Permission denied)"), std::string::npos) << err;
  EXPECT_TRUE(fs::is_empty(t / "ro"));

  ASSERT_EQ(run(train_args(t / "model", 8), t / "train_logs", &err), 0) << err;
  st = run({"eval", scene(), (t / "model").string(), "--protocol", "instances", "--out",
            (t / "ro" / "report.json").string(), "--threads", "2", "--quiet"},
           t / "eval_logs", &err, no_override);
  EXPECT_EQ(st, 1) << err;
  EXPECT_EQ(std::count(err.begin(), err.end(), '\n'), 1) << err;
  EXPECT_NE(err.find("Permission denied"), std::string::npos) << err;
  EXPECT_TRUE(fs::is_empty(t / "ro"));
}

// Numerical faults: HGS_INJECT_NAN=<iteration>:<group> poisons one value of that gradient (or the photometric
// loss) at that iteration.
TEST_F(CrashSafety, InjectedNanStopsTrainingAndKeepsTheLastCheckpoint) {
  test::TempDir t;
  for (const std::string group : {"opacity", "mean", "sh", "loss"}) {
    SCOPED_TRACE(group);
    const fs::path out = t / group;
    std::string err;
    ASSERT_EQ(run(train_args(out, 16), t / (group + "_logs0"), &err), 0) << err;
    const fs::path ckpt = out / "checkpoints" / "iter_16.ckpt";
    const std::vector<uint8_t> before = read_file_bytes(ckpt), ply = read_file_bytes(out / "point_cloud.ply");
    std::vector<std::string> args = train_args(out, 30);
    args.insert(args.end(), {"--resume", ckpt.string()});
    const int st =
        run(args, t / (group + "_logs1"), &err, [group] { ::setenv("HGS_INJECT_NAN", ("21:" + group).c_str(), 1); });
    EXPECT_EQ(st, 1) << err;
    EXPECT_EQ(std::count(err.begin(), err.end(), '\n'), 1) << err;
    EXPECT_NE(err.find("iteration 21"), std::string::npos) << err;
    if (group == "loss") EXPECT_NE(err.find("the 'rgb' loss is nan"), std::string::npos) << err;
    else EXPECT_NE(err.find("parameter group '" + group + "' (1 values); training stopped"), std::string::npos) << err;
    EXPECT_NE(err.find("the last checkpoint " + ckpt.string() + " is intact"), std::string::npos) << err;
    EXPECT_TRUE(read_file_bytes(ckpt) == before);
    EXPECT_TRUE(read_file_bytes(out / "point_cloud.ply") == ply);  // not overwritten by a poisoned model
    EXPECT_FALSE(fs::exists(out / "checkpoints" / "iter_24.ckpt"));
    EXPECT_TRUE(test::incomplete_outputs(out).empty()) << join(test::incomplete_outputs(out));
  }
}

}  // namespace
}  // namespace hgs
