// `hgs prepare` under hostile use (issue 60), with a fake `colmap` (fake_colmap.py, given with --colmap) that
// runs the pose stages in milliseconds and can misbehave as a full disk or a kill makes COLMAP misbehave: a COLMAP
// step that exits 0 having done too little fails its stage; a run locks its scene folder and its COLMAP dies with
// it (SIGTERM or SIGKILL); the input path as typed, the directory a run starts in and a copied scene keep every
// stage; changing one option reruns its stage and the later ones and nothing else; paths too long or unreachable
// are one line. Skips without python3 (the fake is a Python script).
#include <fcntl.h>
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <linux/capability.h>
#include <signal.h>
#include <spawn.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <random>
#include <set>
#include <thread>

#include "core/image.h"
#include "prepare/run_tool.h"
#include "scene/colmap.h"
#include "test_util.h"

extern char** environ;

namespace hgs::test {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;

#define REQUIRE_PYTHON() \
  if (!prepare::find_program("python3")) GTEST_SKIP() << "python3 is absent (the fake colmap needs it): skipping"

fs::path photos(const TempDir& t, int n) {
  const fs::path dir = t / "photos";
  fs::create_directories(dir);
  for (int i = 0; i < n; ++i) texture_png(dir / fmt::format("p{}.png", i), 64, 48, 7u + unsigned(i));
  return dir;
}

// The fake colmap in t/colmap/ with `cfg` as its fake_colmap.json; returns the program to give --colmap.
fs::path fake_colmap(const TempDir& t, const json& cfg = json::object()) {
  const fs::path dir = t / "colmap", exe = dir / "fake_colmap.py";
  fs::create_directories(dir);
  if (!fs::exists(exe)) {
    fs::copy_file(fs::path(HGS_SOURCE_DIR) / "tests" / "prepare" / "fake_colmap.py", exe);
    fs::permissions(exe, fs::perms::owner_all | fs::perms::group_read | fs::perms::group_exec);
  }
  std::ofstream(dir / "fake_colmap.json") << cfg.dump();
  return exe;
}

json read_json(const fs::path& p) { return json::parse(std::ifstream(p)); }

bool one_line(const std::string& s) { return std::count(s.begin(), s.end(), '\n') <= 1; }

bool stage_done(const fs::path& scene, const std::string& stage) {
  const fs::path f = scene / "prepare" / "state.json";
  if (!fs::exists(f)) return false;
  json j = read_json(f);
  return j.contains(stage) && j[stage].value("done", false);
}

// The stages the last run did (not kept from an earlier one), from SCENE/prepare.json.
std::set<std::string> rerun(const fs::path& scene) {
  std::set<std::string> s;
  const json j = read_json(scene / "prepare.json");
  for (const json& st : j["stages"])
    if (!st["reused"].get<bool>()) s.insert(st["stage"].get<std::string>());
  return s;
}

// `hgs args` run in `dir` (the directory a run starts in matters to relative paths).
RunResult run_hgs_in(const fs::path& dir, const std::string& args) {
  TempDir t;
  const std::string cmd = "cd '" + dir.string() + "' && " + HGS_BINARY + " " + args + " >" + (t / "out").string() +
                          " 2>" + (t / "err").string();
  const int st = std::system(cmd.c_str());
  auto slurp = [](const fs::path& p) {
    std::ifstream in(p);
    return std::string(std::istreambuf_iterator<char>(in), {});
  };
  return {WIFEXITED(st) ? WEXITSTATUS(st) : -1, slurp(t / "out"), slurp(t / "err")};
}

// Whether `pid` runs (a zombie, or a process that is gone, does not).
bool alive(pid_t pid) {
  std::ifstream f("/proc/" + std::to_string(pid) + "/stat");
  std::string stat;
  if (!std::getline(f, stat)) return false;
  const size_t close = stat.rfind(')');
  return close != std::string::npos && close + 2 < stat.size() && stat[close + 2] != 'Z';
}

// Waits up to `seconds` for `done`.
bool wait_for(const std::function<bool()>& done, double seconds) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (std::chrono::steady_clock::now() < end) {
    if (done()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return done();
}

// `hgs args...` started in the background (output to /dev/null); returns its pid.
pid_t start_hgs(const std::vector<std::string>& args) {
  std::vector<std::string> a{HGS_BINARY};
  a.insert(a.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& s : a) argv.push_back(s.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 1, "/dev/null", O_WRONLY, 0);
  posix_spawn_file_actions_addopen(&fa, 2, "/dev/null", O_WRONLY, 0);
  pid_t pid = 0;
  EXPECT_EQ(posix_spawn(&pid, HGS_BINARY, &fa, nullptr, argv.data(), environ), 0);
  posix_spawn_file_actions_destroy(&fa);
  return pid;
}

// `hgs args` (through sh) with the permission bits binding even for root: the child drops the capabilities that
// bypass them from its bounding set before exec (as tests/train/test_crash_safety.cpp). Exit 125: cannot drop.
RunResult run_hgs_bound_by_permissions(const std::string& args) {
  TempDir t;
  const std::string cmd =
      std::string(HGS_BINARY) + " " + args + " >" + (t / "out").string() + " 2>" + (t / "err").string();
  const pid_t pid = fork();
  if (pid == 0) {
    if (geteuid() == 0)
      for (int cap : {CAP_DAC_OVERRIDE, CAP_DAC_READ_SEARCH, CAP_FOWNER})
        if (prctl(PR_CAPBSET_DROP, cap, 0, 0, 0) != 0) _exit(125);
    execl("/bin/sh", "sh", "-c", cmd.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  int st = 0;
  waitpid(pid, &st, 0);
  auto slurp = [](const fs::path& p) {
    std::ifstream in(p);
    return std::string(std::istreambuf_iterator<char>(in), {});
  };
  return {WIFEXITED(st) ? WEXITSTATUS(st) : -1, slurp(t / "out"), slurp(t / "err")};
}

pid_t read_pid(const fs::path& f) {
  std::ifstream in(f);
  long pid = 0;
  in >> pid;
  return pid_t(pid);
}

// Issue 60, item 4: COLMAP logs "database or disk is full" and exits 0 with 3 of 4 images in its database; the
// features stage used to be recorded complete (and every rerun kept it).
TEST(PrepareHostile, AColmapStepThatExitsZeroHavingDoneTooLittleFailsItsStage) {
  REQUIRE_PYTHON();
  TempDir t;
  const fs::path in = photos(t, 4), out = t / "scene";
  const fs::path colmap = fake_colmap(t, {{"drop_last_feature", true}});
  const std::string args = "prepare " + in.string() + " --out " + out.string() + " --colmap " + colmap.string() +
                           " --until features --quiet";
  RunResult r = run_hgs(args);
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("only 3 of 4 images"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("p3.png"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("disk full"), std::string::npos) << r.err;
  EXPECT_TRUE(one_line(r.err)) << r.err;
  EXPECT_FALSE(stage_done(out, "features"));
  EXPECT_FALSE(fs::exists(out / "prepare.json"));
  fake_colmap(t);  // space again: the rerun redoes the stage
  r = run_hgs(args);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(stage_done(out, "features"));
}

// Issue 60, items 6 and 14: a second run into the same --out is refused naming the folder and the pid; SIGTERM
// or SIGKILL to hgs ends its COLMAP (which used to run on for a minute, so that a rerun found the database
// locked), and a rerun right after proceeds.
TEST(PrepareHostile, ARunLocksItsSceneAndItsColmapDiesWithIt) {
  REQUIRE_PYTHON();
  TempDir t;
  const fs::path in = photos(t, 3), out = t / "scene";
  const fs::path colmap = fake_colmap(t, {{"sleep_in", "feature_extractor"}}), pid_file = t / "colmap" / "pid";
  const std::vector<std::string> args{"prepare",  in.string(),     "--out",  out.string(),
                                      "--colmap", colmap.string(), "--quiet"};
  for (int sig : {SIGTERM, SIGKILL}) {
    SCOPED_TRACE(strsignal(sig));
    fs::remove(pid_file);
    const pid_t hgs = start_hgs(args);
    ASSERT_TRUE(wait_for([&] { return fs::exists(pid_file); }, 20)) << "the fake colmap did not start";
    const pid_t child = read_pid(pid_file);
    ASSERT_GT(child, 0);
    EXPECT_TRUE(alive(child));
    RunResult second =
        run_hgs("prepare " + in.string() + " --out " + out.string() + " --colmap " + colmap.string() + " --quiet");
    EXPECT_NE(second.exit_code, 0);
    EXPECT_NE(second.err.find(out.string() + ": another hgs prepare (pid " + std::to_string(hgs) + ")"),
              std::string::npos)
        << second.err;
    EXPECT_TRUE(one_line(second.err)) << second.err;
    kill(hgs, sig);
    int status = 0;
    waitpid(hgs, &status, 0);
    EXPECT_TRUE(wait_for([&] { return !alive(child); }, 5)) << "colmap outlived hgs";
    if (alive(child)) kill(child, SIGKILL);
  }
  fake_colmap(t);
  RunResult r = run_hgs("prepare " + in.string() + " --out " + out.string() + " --colmap " + colmap.string() +
                        " --until poses --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(fs::exists(out / "sparse" / "0" / "images.bin"));
}

// Issue 60, item 9: `photos`, `photos/`, `./photos`, the absolute path and a link to the folder are one input:
// a rerun keeps every stage. A photo replaced by another of the same size reruns them all.
TEST(PrepareHostile, TheInputPathAsTypedKeepsEveryStageAndNewContentRerunsThem) {
  REQUIRE_PYTHON();
  TempDir t;
  photos(t, 4);
  const fs::path colmap = fake_colmap(t);
  const std::string rest = " --out scene --colmap " + colmap.string() + " --until poses --quiet";
  RunResult r = run_hgs_in(t.path, "prepare photos" + rest);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(rerun(t / "scene").size(), 7u);
  fs::create_directory_symlink(t / "photos", t / "link");
  for (const std::string& typed : {std::string("photos/"), std::string("./photos"), (t / "photos").string(),
                                   std::string("link"), std::string("../") + t.path.filename().string() + "/photos"}) {
    r = run_hgs_in(t.path, "prepare " + typed + rest);
    ASSERT_EQ(r.exit_code, 0) << typed << ": " << r.err;
    EXPECT_EQ(rerun(t / "scene"), std::set<std::string>{}) << typed;
  }
  texture_png(t / "photos" / "p2.png", 64, 48, 1234u);
  r = run_hgs_in(t.path, "prepare photos" + rest);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(rerun(t / "scene"), (std::set<std::string>{"input", "features", "matching", "mapping", "retry_mapping",
                                                       "retry_features", "undistort"}));
}

// Issue 60, item 10: the mapping record names the model relative to the scene: a run from another directory, and
// a copy of the scene whose original is gone, resume at undistort; a record from before (a path relative to the
// directory the first run started in) is read the same way.
TEST(PrepareHostile, AResumeFromAnotherDirectoryOrACopiedSceneReadsItsOwnModel) {
  REQUIRE_PYTHON();
  TempDir t;
  photos(t, 4);
  const fs::path colmap = fake_colmap(t);
  const std::string opts = " --colmap " + colmap.string() + " --quiet";
  RunResult r = run_hgs_in(t.path, "prepare photos --out scene --until mapping" + opts);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(read_json(t / "scene" / "prepare" / "state.json")["mapping"]["info"]["model_path"], "prepare/sparse/0");
  fs::create_directories(t / "elsewhere");
  r = run_hgs_in(t / "elsewhere", "prepare ../photos --out ../scene --until poses" + opts);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(rerun(t / "scene"), (std::set<std::string>{"retry_mapping", "retry_features", "undistort"}));

  // A copy made after mapping, with the record as runs before this fix wrote it; the original is gone.
  fs::remove_all(t / "scene" / "sparse");
  fs::remove_all(t / "scene" / "images");
  json state = read_json(t / "scene" / "prepare" / "state.json");
  state.erase("undistort");
  for (const char* stage : {"mapping", "retry_mapping", "retry_features"}) {
    state[stage]["info"].erase("model_path");
    state[stage]["info"]["model"] = "scene/prepare/sparse/0";
  }
  std::ofstream(t / "scene" / "prepare" / "state.json") << state.dump(2);
  fs::copy(t / "scene", t / "copy", fs::copy_options::recursive);
  fs::remove_all(t / "scene");
  r = run_hgs_in(t / "elsewhere", "prepare ../photos --out ../copy --until poses" + opts);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(rerun(t / "copy"), std::set<std::string>{"undistort"});
  EXPECT_TRUE(fs::exists(t / "copy" / "sparse" / "0" / "images.bin"));
  EXPECT_FALSE(fs::exists(t / "scene"));
}

// The stage keys end to end (test_stage_keys.cpp checks them without running stages): each row adds one option
// to the run before it, which reruns that option's stage and the stages after it that read it; changing nothing,
// or an option no stage output depends on, reruns nothing.
TEST(PrepareHostile, ChangingOneOptionRerunsItsStageAndTheLaterOnesOnly) {
  REQUIRE_PYTHON();
  TempDir t;
  const fs::path in = photos(t, 3), out = t / "scene";
  const fs::path colmap = fake_colmap(t);
  std::string args =
      "prepare " + in.string() + " --out " + out.string() + " --colmap " + colmap.string() + " --until poses --quiet";
  ASSERT_EQ(run_hgs(args).exit_code, 0);
  const std::set<std::string> poses{"features", "matching", "mapping", "retry_mapping", "retry_features", "undistort"};
  struct Row {
    std::string option;
    std::set<std::string> stages;
  };
  const std::vector<Row> rows = {
      {"", {}},
      {"--max-features 2048", poses},
      {"--camera-model PINHOLE", poses},
      {"--matcher sequential", {"matching", "mapping", "retry_mapping", "retry_features", "undistort"}},
      {"--max-size 32", {"input", "features", "matching", "mapping", "retry_mapping", "retry_features", "undistort"}},
      {"--max-pixels 100000000", {}},  // the same photos pass: the same outputs
      {"--allow-partial", {}},
  };
  for (const Row& row : rows) {
    args += " " + row.option;
    RunResult r = run_hgs(args);
    ASSERT_EQ(r.exit_code, 0) << row.option << ": " << r.err;
    EXPECT_EQ(rerun(out), row.stages) << row.option;
  }
}

// Issue 60, "Sparse captures": fewer than half the photos registered -> COLMAP's wide-baseline mapper options,
// then wide-baseline features with guided matching, each said in the progress and the report; the model with
// the most images is kept; a rerun keeps every step. A capture no step saves is refused naming what was tried
// and advising only what was not.
TEST(PrepareHostile, ASparseCaptureIsRetriedWithWideBaselineSettings) {
  REQUIRE_PYTHON();
  TempDir t;
  const fs::path in = photos(t, 6), out = t / "scene";
  // Defaults: 2 images (no model, as COLMAP below 3), the wide mapper: 2, wide features too: 5.
  const fs::path colmap = fake_colmap(t, {{"register", 2}, {"robust_register", 2}, {"affine_register", 5}});
  const std::string args =
      "prepare " + in.string() + " --out " + out.string() + " --colmap " + colmap.string() + " --until poses";
  RunResult r = run_hgs(args);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const json p = read_json(out / "prepare.json")["poses"];
  EXPECT_EQ(p["registered"], 5) << p.dump();
  EXPECT_EQ(p["settings"], "wide-baseline features");
  EXPECT_EQ(p["retried"], json({"wide-baseline mapper: 0 of 6", "wide-baseline features: 5 of 6"}));
  EXPECT_NE(r.err.find("retrying with COLMAP's wide-baseline mapper options"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("retrying with wide-baseline features"), std::string::npos) << r.err;
  EXPECT_NE(r.out.find("retried (fewer than half registered): wide-baseline mapper: 0 of 6"), std::string::npos)
      << r.out;
  EXPECT_EQ(read_colmap(out / "sparse" / "0").images.size(), 5u);
  auto calls = [&](const std::string& sub) {
    std::ifstream f(t / "colmap" / "calls.log");
    int n = 0;
    for (std::string line; std::getline(f, line);) n += line.rfind(sub + " ", 0) == 0;
    return n;
  };
  EXPECT_EQ(calls("mapper"), 3);
  EXPECT_EQ(calls("feature_extractor"), 2);
  r = run_hgs(args + " --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(rerun(out), std::set<std::string>{});
  EXPECT_EQ(calls("mapper"), 3) << "a rerun keeps the retries";

  // Nothing helps: refused after both retries, without advising the exhaustive matcher that ran.
  fake_colmap(t, {{"register", 3}, {"robust_register", 3}, {"affine_register", 3}});
  const fs::path in8 = t / "photos8", out8 = t / "scene8";
  fs::create_directories(in8);
  for (int i = 0; i < 8; ++i) texture_png(in8 / fmt::format("q{}.png", i), 64, 48, 50u + unsigned(i));
  const std::string args8 =
      "prepare " + in8.string() + " --out " + out8.string() + " --colmap " + colmap.string() + " --quiet";
  r = run_hgs(args8);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("registered only 3 of 8 images"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("retried: wide-baseline mapper: 3 of 8; wide-baseline features: 3 of 8"), std::string::npos)
      << r.err;
  EXPECT_EQ(r.err.find("--matcher exhaustive"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("--allow-partial"), std::string::npos) << r.err;
  EXPECT_TRUE(one_line(r.err)) << r.err;
  r = run_hgs(args8 + " --allow-partial --until poses");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(read_json(out8 / "prepare.json")["poses"]["registered"], 3);
}

// Issue 60, item 12: a name over 255 bytes in INPUT or --out, or a folder on the way that cannot be searched (as
// root too: the capabilities that bypass permissions are dropped), is one line naming the path (it was
// "internal error: filesystem error", exit 2).
TEST(PrepareHostile, PathsTooLongOrUnreachableAreOneLineNamingThem) {
  TempDir t;
  const fs::path in = photos(t, 3), long_name = t / std::string(300, 'a');
  RunResult r = run_hgs("prepare " + long_name.string() + " --out " + (t / "scene").string() + " --quiet");
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find(long_name.string() + ": a name in the INPUT path is 300 bytes"), std::string::npos) << r.err;
  EXPECT_TRUE(one_line(r.err)) << r.err;
  const fs::path long_out = t / std::string(300, 'b') / "scene";
  r = run_hgs("prepare " + in.string() + " --out " + long_out.string() + " --until input --quiet");
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find(long_out.string() + ": a name in the --out path"), std::string::npos) << r.err;
  EXPECT_TRUE(one_line(r.err)) << r.err;
  fs::create_directories(t / "closed" / "photos");
  fs::permissions(t / "closed", fs::perms::none);
  r = run_hgs_bound_by_permissions("prepare " + (t / "closed" / "photos").string() + " --out " +
                                   (t / "scene").string() + " --quiet");
  if (r.exit_code == 125) {
    fs::permissions(t / "closed", fs::perms::owner_all);
    GTEST_SKIP() << "cannot drop CAP_DAC_OVERRIDE here (root searches any folder)";
  }
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find((t / "closed" / "photos").string() + ": cannot reach the INPUT (Permission denied)"),
            std::string::npos)
      << r.err;
  EXPECT_TRUE(one_line(r.err)) << r.err;
  r = run_hgs_bound_by_permissions("prepare " + in.string() + " --out " + (t / "closed" / "scene").string() +
                                   " --quiet");
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find((t / "closed" / "scene").string() + ": cannot reach the --out (Permission denied)"),
            std::string::npos)
      << r.err;
  EXPECT_TRUE(one_line(r.err)) << r.err;
  fs::permissions(t / "closed", fs::perms::owner_all);
}

// Issues 60, items 5, 11 and 13 through the command: renamed photos and links to nothing in prepare.json and the
// report, --max-pixels on the command line.
TEST(PrepareHostile, TheReportListsRenamedPhotosAndBrokenLinksAndMaxPixelsIsSettable) {
  TempDir t;
  const fs::path in = photos(t, 3), out = t / "scene";
  fs::copy_file(in / "p0.png", in / "win\\dir\\p9.png");
  fs::create_symlink(t / "gone.png", in / "z.png");
  RunResult r = run_hgs("prepare " + in.string() + " --out " + out.string() + " --until input --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const json j = read_json(out / "prepare.json");
  EXPECT_EQ(j["input"]["images"], 4);
  ASSERT_EQ(j["input"]["renamed"].size(), 1u);
  EXPECT_EQ(j["input"]["renamed"][0][1], "win_dir_p9.png");
  ASSERT_EQ(j["input"]["broken_links"].size(), 1u);
  EXPECT_NE(r.out.find("renamed (names COLMAP cannot carry)"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("win_dir_p9.png"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("skipped (links to nothing): " + (in / "z.png").string()), std::string::npos) << r.out;
  EXPECT_TRUE(fs::exists(out / "prepare" / "input" / "win_dir_p9.png"));
  r = run_hgs("prepare " + in.string() + " --out " + (t / "scene2").string() +
              " --until input --quiet --max-pixels 3000");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("64x48"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("--max-pixels"), std::string::npos) << r.err;
  EXPECT_TRUE(one_line(r.err)) << r.err;
}

}  // namespace
}  // namespace hgs::test
