#include "test_util.h"

#include <sys/wait.h>

#include <cstdio>
#include <fstream>
#include <random>
#include <sstream>

#include "core/error.h"
#include "core/image.h"

namespace hgs::test {
namespace fs = std::filesystem;

TempDir::TempDir() {
  std::random_device rd;
  path = fs::temp_directory_path() / ("hgs_test_" + std::to_string(rd()) + std::to_string(rd()));
  fs::create_directories(path);
}

TempDir::~TempDir() {
  std::error_code ec;
  if (!std::getenv("HGS_KEEP_TEST_DIRS")) fs::remove_all(path, ec);
}

RunResult run_hgs(const std::string& args) {
  TempDir t;
  std::string cmd = std::string(HGS_BINARY) + " " + args + " >" + (t / "out").string() + " 2>" + (t / "err").string();
  int st = std::system(cmd.c_str());
  auto slurp = [](const fs::path& p) {
    std::ifstream in(p);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
  };
  return {WIFEXITED(st) ? WEXITSTATUS(st) : -1, slurp(t / "out"), slurp(t / "err")};
}

fs::path shared_data(const std::string& name) {
  fs::path p = fs::path(HGS_SHARED_DIR) / "data" / name;
  return fs::is_directory(p) ? p : fs::path();
}

std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

void texture_png(const fs::path& p, int w, int h, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.f, 1.f);
  Image img(w, h, 3);
  for (float& v : img.px) v = u(rng);
  save_png(p, img);
}

}  // namespace hgs::test
