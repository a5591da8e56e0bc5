// Cost at real-capture scale: one training step of each method at 1000x700 pixels with 300k Gaussians (a LERF
// scene at full resolution), and how it grows with the pixels and with the Gaussians (0.25x, 1x and 4x of each),
// with the peak resident memory of each case. Methods: `rgb` (plain 3DGS), `hybrid` (the hybrid method's object
// terms only: eqs. 6 and 14, association, fusion; the scene's data has no SCL classes, so no language term) and
// `full` (the same with every view's SCL classes set as load_hybrid_data sets them: also the language term,
// eqs. 9-10, D = 512, as `hgs train` runs it and as the paper times it). Scene: bench_hybrid_scene.h at W x H
// with n Gaussians (scales / cbrt(n / 30k), so the box is covered alike), two views, K = 8 objects, densification
// off. Every case runs in a child process (this program re-runs itself with --case), so each peak RSS is that
// case's own: the model, the optimiser, the renderer's buffers and the two training images. Prints a markdown
// table (README "Benchmarks"), the parts of the base case's steps (train::StepTimes) and, with --json FILE, the
// figures as JSON.
// --fusion-every K rebuilds the hybrid method's observation table every K images (default: HybridConfig's), so
// that with K = 1 every timed step carries a rebuild, reported in the part `densify` (the method's after-step
// work): the rebuild's cost per view, as its own part (issue 61, goal 3).
//   build/bench_scale [--steps 4] [--threads 2] [--objects-per-step M] [--fusion-every K] [--json FILE]
//   build/bench_scale --case rgb|hybrid|full PIXELS GAUSSIANS [options]   (one case, one JSON line)
#include <dlfcn.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <map>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <omp.h>
#include <nlohmann/json.hpp>

#include "bench_hybrid_scene.h"
#include "core/process.h"
#include "hybrid/method.h"
#include "train/trainer.h"
#include "wait_policy.h"

using namespace hgs;
using nlohmann::json;

namespace {

constexpr int kBaseW = 1000, kBaseH = 700, kBaseN = 300000;

struct Args {
  int steps = 4, threads = 2, objects_per_step = hybrid::HybridConfig{}.objects_per_step;
  int fusion_every = hybrid::HybridConfig{}.fusion_every;
  std::string json_out;
};

// One timed step, in a call of its own so that bench/ll_traffic.py can count inside the timed steps only (callgrind's
// --toggle-collect=hgs::bench::timed_step*), not the warm-up steps' first touches of their buffers.
}  // namespace
namespace hgs::bench {
__attribute__((noinline)) train::StepInfo timed_step(train::Trainer& trainer) { return trainer.step(); }
}  // namespace hgs::bench
namespace {

// One case in this process: one warm-up step per view (the trainer visits every view once per shuffled round, so
// every view's buffers have their size before the timing), then `steps` timed steps. Prints one JSON line.
int run_case(const std::string& method, double pixels, double gaussians, const Args& a) {
  omp_set_num_threads(a.threads);
  const int W = int(std::lround(kBaseW * std::sqrt(pixels))), H = int(std::lround(kBaseH * std::sqrt(pixels)));
  const int n = int(std::lround(kBaseN * gaussians));
  bench::HybridScene s(W, H, n, 1.f / std::cbrt(float(n) / float(bench::kN)));
  train::TrainConfig cfg;
  cfg.densify = false;
  cfg.sh_increase_every = 0;  // full SH degree 3 from the first step
  cfg.iters = 1000000;
  std::unique_ptr<train::Method> m;
  if (method == "hybrid" || method == "full") {
    hybrid::HybridConfig hc;
    hc.objects_per_step = a.objects_per_step;
    hc.fusion_every = a.fusion_every;
    m = std::make_unique<hybrid::HybridMethod>(hc, method == "full" ? bench::with_scl(s.data, hc) : s.data, cfg.seed);
  } else if (method != "rgb") {
    std::fprintf(stderr, "bench_scale: unknown method '%s' (rgb, hybrid, full)\n", method.c_str());
    return 2;
  }
  const size_t num_views = s.views.size();
  train::Trainer trainer(cfg, std::move(s.model), s.views, 5.f, std::move(m));
  for (size_t i = 0; i < std::max<size_t>(1, num_views); ++i) trainer.step();
  // Under bench/project_threads.py's LD_PRELOAD library (bench/omp_regions): its tables start here, at the timed
  // steps. Absent otherwise.
  if (auto reset = reinterpret_cast<void (*)()>(dlsym(RTLD_DEFAULT, "hgs_regions_reset"))) reset();
  std::vector<double> ms;
  std::vector<train::StepTimes> parts;
  std::map<std::string, std::vector<double>> method_parts;  // the method's own timers (ms_*) and task counts, per step
  for (int i = 0; i < a.steps; ++i) {
    const auto t0 = std::chrono::steady_clock::now();
    const train::StepInfo info = bench::timed_step(trainer);
    ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    parts.push_back(info.times);
    for (const auto& [k, v] : trainer.method().stats().values)
      if (k.starts_with("ms_") || k.starts_with("tasks_")) method_parts[k].push_back(v);
    if (!std::isfinite(info.total)) {
      std::fprintf(stderr, "bench_scale: the %s step's loss is not finite\n", method.c_str());
      return 1;
    }
  }
  json part_ms = json::object();  // the median of each part over the timed steps
  train::StepTimes::each([&](const char* name, double train::StepTimes::*m) {
    std::vector<double> v;
    for (const auto& t : parts) v.push_back(t.*m);
    std::sort(v.begin(), v.end());
    part_ms[name] = v[v.size() / 2];
  });
  json tasks = json::object();         // the object losses' task counts (tasks_app_pieces, ...), medians over the steps
  for (auto& [k, v] : method_parts) {  // e.g. the object losses' phases: method_ms_app_boxes, ...
    std::sort(v.begin(), v.end());
    if (k.starts_with("tasks_")) tasks[k.substr(6)] = v[v.size() / 2];
    else part_ms["method_" + k] = v[v.size() / 2];
  }
  std::sort(ms.begin(), ms.end());
  const json j = {{"parts_ms", part_ms},
                  {"tasks", tasks},
                  {"method", method},
                  {"width", W},
                  {"height", H},
                  {"gaussians", n},
                  {"ms_median", ms[ms.size() / 2]},
                  {"ms_min", ms.front()},
                  {"peak_rss_mb", peak_rss_mb()}};
  std::printf("%s\n", j.dump().c_str());
  return 0;
}

std::string self_path() {
  char buf[4096];
  const ssize_t k = readlink("/proc/self/exe", buf, sizeof(buf) - 1);
  if (k <= 0) return "bench_scale";
  buf[k] = 0;
  return buf;
}

json run_child(const std::string& method, double pixels, double gaussians, const Args& a) {
  const std::string cmd =
      fmt::format("'{}' --case {} {} {} --steps {} --threads {} --objects-per-step {} --fusion-every {}", self_path(),
                  method, pixels, gaussians, a.steps, a.threads, a.objects_per_step, a.fusion_every);
  FILE* p = popen(cmd.c_str(), "r");
  if (!p) return nullptr;
  std::string out;
  char buf[1024];
  while (std::fgets(buf, sizeof(buf), p)) out += buf;
  if (pclose(p) != 0) return nullptr;
  try {
    return json::parse(out);
  } catch (const std::exception&) {
    return nullptr;
  }
}

int usage(const char* why) {
  std::fprintf(
      stderr,
      "bench_scale: %s\nusage: bench_scale [--steps N] [--threads T] [--objects-per-step M] [--fusion-every K] "
      "[--json FILE]\n",
      why);
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  Args a;
  std::string case_method;
  double case_p = 0, case_g = 0;
  for (int i = 1; i < argc; ++i) {
    const std::string k = argv[i];
    auto next = [&]() -> const char* { return i + 1 < argc ? argv[++i] : nullptr; };
    const char* v = nullptr;
    if (k == "--help" || k == "-h") {
      std::printf(
          "Training step time and peak memory at 1000x700 / 300k Gaussians and at 0.25x and 4x the pixels\n"
          "and the Gaussians (one child process per case): rgb (plain 3DGS), hybrid (the object terms only),\n"
          "full (the object terms and the language term, SCL with D = 512, as hgs train runs the method).\n"
          "  --case METHOD PIXELS GAUSSIANS   one case (rgb, hybrid or full), one JSON line\n"
          "usage: bench_scale [--steps N] [--threads T] [--objects-per-step M] [--fusion-every K] [--json FILE]\n");
      return 0;
    } else if (k == "--case") {
      if (i + 3 >= argc) return usage("--case needs METHOD PIXELS GAUSSIANS");
      case_method = argv[++i];
      case_p = std::atof(argv[++i]);
      case_g = std::atof(argv[++i]);
    } else if (k == "--steps" && (v = next())) {
      a.steps = std::max(1, std::atoi(v));
    } else if (k == "--threads" && (v = next())) {
      a.threads = std::max(1, std::atoi(v));
    } else if (k == "--objects-per-step" && (v = next())) {
      a.objects_per_step = std::max(0, std::atoi(v));
    } else if (k == "--fusion-every" && (v = next())) {
      a.fusion_every = std::max(1, std::atoi(v));
    } else if (k == "--json" && (v = next())) {
      a.json_out = v;
    } else {
      return usage(("unknown or incomplete option " + k).c_str());
    }
  }
  if (!case_method.empty()) return run_case(case_method, case_p, case_g, a);
  hgs::bench::omp_wait_policy_checked();  // warns when passive (wait_policy.h)

  std::printf(
      "%d threads, median of %d steps after one warm-up step per view, hybrid objects_per_step %d (0 = exact)\n\n",
      a.threads, a.steps, a.objects_per_step);
  std::printf(
      "hybrid: the object terms only (no SCL classes in the scene's data); full: the object terms and the language\n"
      "term (SCL, D = 512), the method as hgs train runs it\n\n");
  std::printf(
      "| pixels | Gaussians | RGB ms/step | hybrid ms/step | full ms/step | hybrid / RGB | full / RGB "
      "| RGB peak RSS MB | hybrid peak RSS MB | full peak RSS MB |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|\n");
  json all = json::array();
  const double cases[][2] = {{1, 1}, {0.25, 1}, {4, 1}, {1, 0.25}, {1, 4}};
  for (const auto& c : cases) {
    const json r = run_child("rgb", c[0], c[1], a), h = run_child("hybrid", c[0], c[1], a),
               f = run_child("full", c[0], c[1], a);
    auto ms = [](const json& j) {
      return j.is_null() ? std::string("failed") : fmt::format("{:.0f}", j["ms_median"].get<double>());
    };
    auto mb = [](const json& j) {
      return j.is_null() ? std::string("-") : fmt::format("{:.0f}", j["peak_rss_mb"].get<double>());
    };
    const json& any = r.is_null() ? h : r;
    const std::string px =
        any.is_null() ? "?" : fmt::format("{}x{} ({}x)", any["width"].get<int>(), any["height"].get<int>(), c[0]);
    const std::string ng = any.is_null() ? "?" : fmt::format("{}k ({}x)", any["gaussians"].get<int>() / 1000, c[1]);
    auto ratio = [&](const json& j) {
      return r.is_null() || j.is_null()
                 ? std::string("-")
                 : fmt::format("{:.2f}x", j["ms_median"].get<double>() / r["ms_median"].get<double>());
    };
    std::printf("| %s | %s | %s | %s | %s | %s | %s | %s | %s | %s |\n", px.c_str(), ng.c_str(), ms(r).c_str(),
                ms(h).c_str(), ms(f).c_str(), ratio(h).c_str(), ratio(f).c_str(), mb(r).c_str(), mb(h).c_str(),
                mb(f).c_str());
    std::fflush(stdout);
    all.push_back({{"pixels", c[0]}, {"gaussians", c[1]}, {"rgb", r}, {"hybrid", h}, {"full", f}});
  }
  // Where the time of the base case goes (medians of each part; they need not add up to the step's median).
  const json& base = all[0];
  if (!base["rgb"].is_null() && !base["hybrid"].is_null() && !base["full"].is_null()) {
    std::printf(
        "\nParts of the 1000x700 / 300k steps, ms (median over the steps):\n\n| part | RGB | hybrid | full "
        "|\n|---|---|---|---|\n");
    for (const auto& [name, v] : base["full"]["parts_ms"].items())
      std::printf("| %s | %.1f | %.1f | %.1f |\n", name.c_str(), base["rgb"]["parts_ms"].value(name, 0.0),
                  base["hybrid"]["parts_ms"].value(name, 0.0), v.get<double>());
  }
  // The object losses' phases that are not cut by rows: their task counts at this thread count (the pieces are
  // cut into bands by the thread count: with --threads 16 on any machine, the count a 16-core run has).
  std::printf(
      "\nTasks of the hybrid step's object losses at %d threads (pieces: bands of the scoring tasks; finish: "
      "one per object for its scalars, then bands of its rows):\n\n| pixels / Gaussians | pieces | finish "
      "|\n|---|---|---|\n",
      a.threads);
  for (const json& c : all) {
    const json& h = c["hybrid"];
    if (h.is_null() || !h.contains("tasks")) continue;
    std::printf("| %dx%d / %dk | %.0f | %.0f |\n", h["width"].get<int>(), h["height"].get<int>(),
                h["gaussians"].get<int>() / 1000, h["tasks"].value("app_pieces", 0.0),
                h["tasks"].value("app_finish", 0.0));
  }
  if (!a.json_out.empty()) {
    FILE* f = std::fopen(a.json_out.c_str(), "w");
    if (!f) return usage(("cannot write " + a.json_out).c_str());
    std::fprintf(f, "%s\n", all.dump(2).c_str());
    std::fclose(f);
  }
  return 0;
}
