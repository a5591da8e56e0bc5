// Shared helpers for the GoogleTest suites: temporary folders, running the `hgs` binary, and skipping
// tests whose real data (../shared) is absent.
#pragma once
#include <gtest/gtest.h>

#include <filesystem>
#include <functional>
#include <string>

namespace hgs::test {

// A fresh empty folder under the system temp dir, removed when the object dies.
struct TempDir {
  TempDir();
  ~TempDir();
  std::filesystem::path path;
  std::filesystem::path operator/(const std::string& s) const { return path / s; }
};

struct RunResult {
  int exit_code;
  std::string out;  // stdout
  std::string err;  // stderr
};
// Runs the built `hgs` binary with `args` (a shell-quoted string).
RunResult run_hgs(const std::string& args);

// The message of the hgs::Error that `f` throws, or "" when it throws none (another exception propagates).
std::string error_of(const std::function<void()>& f);

// Path of ../shared/data/<name>, or empty when absent.
std::filesystem::path shared_data(const std::string& name);

// A w x h PNG of random texture (seeded), which no compressor shrinks much: a photo for hgs prepare's tests.
void texture_png(const std::filesystem::path& p, int w, int h, unsigned seed);

}  // namespace hgs::test

#define HGS_REQUIRE_SHARED(var, name)        \
  auto var = ::hgs::test::shared_data(name); \
  if (var.empty()) GTEST_SKIP() << "../shared/data/" name " is absent: skipping real-data test"
