// hgs — command-line entry point. Errors from hgs::Error print one line and exit with status 1.
#include <cblas.h>
#include <omp.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>

#include "cli/command.h"
#include "clip/model.h"
#include "core/error.h"
#include "core/process.h"
#include "core/threads.h"
#include "nn/openblas_env.h"
#include "nn/thread_pool.h"

HGS_OPENBLAS_PREINIT();

namespace hgs::cli {

std::vector<CommandSpec>& registry() {
  static std::vector<CommandSpec> r;
  return r;
}

void set_threads(int threads) { hgs::nn::set_num_threads(threads); }  // OpenMP, the pool and OpenBLAS

CLI::Option* add_threads_option(CLI::App& sub, int& threads, const std::string& what) {
  CLI::Validator bound(
      [](std::string& text) -> std::string {
        long long n = 0;
        size_t used = 0;
        try {
          n = std::stoll(text, &used);
        } catch (const std::exception&) {
          used = 0;
        }
        if (used == 0 || used != text.size()) return "expected a whole number of threads, got '" + text + "'";
        if (n < 1 || n > hgs::max_threads()) return "must be " + hgs::threads_range_text() + ", got " + text;
        return "";
      },
      "1.." + std::to_string(hgs::max_threads()));
  return sub.add_option("--threads", threads, what + ", " + hgs::threads_range_text() + " (default: every CPU)")
      ->check(bound);
}

namespace {

// The default thread count of OpenMP, the element-wise pools and OpenBLAS: the CPUs this process may use (a
// container's CPU quota included, core/process.h), unless OMP_NUM_THREADS / OPENBLAS_NUM_THREADS say otherwise.
void default_threads() {
  if (!std::getenv("OMP_NUM_THREADS")) omp_set_num_threads(std::min(omp_get_max_threads(), hgs::available_cpus()));
  if (!std::getenv("OPENBLAS_NUM_THREADS")) openblas_set_num_threads(omp_get_max_threads());
}

}  // namespace

}  // namespace hgs::cli

int main(int argc, char** argv) {
  using namespace hgs::cli;
  default_threads();
  if (omp_get_max_threads() > hgs::max_threads()) {  // OMP_NUM_THREADS=100000 crashed at the first parallel region
    std::fprintf(stderr, "hgs: error: OMP_NUM_THREADS: must be %s, got %d\n", hgs::threads_range_text().c_str(),
                 omp_get_max_threads());
    return 2;
  }
  CLI::App app{"hgs " HGS_VERSION
               " — Hybrid Gaussians: open-vocabulary 3D segmentation with Gaussian splatting, on the CPU"};
  app.set_version_flag("--version", std::string("hgs ") + HGS_VERSION);
  app.require_subcommand(1);
  app.fallthrough(false);
  auto& reg = registry();
  std::sort(reg.begin(), reg.end(), [](const CommandSpec& a, const CommandSpec& b) { return a.order < b.order; });
  std::function<void()> run;
  for (auto& spec : reg) {
    CLI::App* sub = app.add_subcommand(spec.name, spec.help);
    auto fn = spec.setup(*sub);
    sub->callback([fn, &run] { run = fn; });
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    if (e.get_exit_code() == 0) return app.exit(e);  // --help, --version
    // One line naming the option and what is allowed, like every other error of hgs (CLI11's own message says
    // which option and range; its second line "Run with --help" is folded into this one).
    std::string where = "hgs";
    for (const CLI::App* at = &app; !at->get_subcommands().empty();) {  // nested too: `hgs masks generate`
      at = at->get_subcommands().front();
      where += " " + at->get_name();
    }
    std::fprintf(stderr, "hgs: error: %s (see `%s --help`)\n", e.what(), where.c_str());
    return 2;
  }
  try {
    if (run) run();
  } catch (const hgs::Error& e) {
    std::fprintf(stderr, "hgs: error: %s\n", e.what());
    return 1;
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "hgs: error: out of memory\n");
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "hgs: internal error: %s\n", e.what());
    return 2;
  }
  return 0;
}
