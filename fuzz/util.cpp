// Scratch files, input splitting and the tiny synthetic scene shared by the fuzz harnesses (fuzz.h).
#include <unistd.h>

#include <cstdlib>
#include <system_error>

#include "../tests/synth_options.h"
#include "core/error.h"
#include "core/fs.h"
#include "fuzz.h"
#include "synth/synth.h"

namespace hgs::fuzz {
namespace fs = std::filesystem;

std::map<std::string, Harness>& registry() {
  static std::map<std::string, Harness> r;
  return r;
}

namespace {
const fs::path& root() {
  static const fs::path r = [] {
    std::error_code ec;
    const fs::path base = fs::is_directory("/dev/shm", ec) ? fs::path("/dev/shm") : fs::temp_directory_path();
    fs::path p = base / ("hgs-fuzz-" + std::to_string(::getpid()));
    fs::remove_all(p, ec);
    fs::create_directories(p);
    std::atexit([] {
      std::error_code e;
      fs::remove_all(root(), e);
    });
    return p;
  }();
  return r;
}
}  // namespace

fs::path scratch(const std::string& sub) {
  const fs::path p = root() / sub;
  std::error_code ec;
  fs::remove_all(p, ec);
  fs::create_directories(p);
  return p;
}

void put_file(const fs::path& path, std::string_view bytes) { atomic_write_bytes(path, bytes.data(), bytes.size()); }

std::vector<std::string_view> split(const uint8_t* data, size_t size, size_t n) {
  std::string_view s(reinterpret_cast<const char*>(data), size);
  std::vector<std::string_view> parts;
  while (parts.size() + 1 < n) {
    const size_t at = s.find(kSplit);
    if (at == std::string_view::npos) break;
    parts.push_back(s.substr(0, at));
    s.remove_prefix(at + kSplit.size());
  }
  parts.push_back(s);
  parts.resize(n);
  return parts;
}

const fs::path& tiny_scene() {
  static const fs::path dir = [] {
    fs::path d = root() / "tiny_scene";
    synth::generate(d, hgs::test::SmallSynth().views(4).image_size(32, 24).objects(3).points(200).feature_dim(8).noise(
                           "none"));
    return d;
  }();
  return dir;
}

fs::path scene_skeleton(const std::string& sub) {
  const fs::path& src = tiny_scene();
  const fs::path d = scratch(sub);
  fs::copy(src / "sparse", d / "sparse", fs::copy_options::recursive);
  fs::copy(src / "images", d / "images", fs::copy_options::recursive);
  return d;
}

}  // namespace hgs::fuzz
