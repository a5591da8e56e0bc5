// Shared pieces of the fuzz harnesses (fuzz_<name>.cpp). HGS_FUZZ_TARGET(name) opens a harness body over
// (data, size): with libFuzzer (HGS_LIBFUZZER) it is LLVMFuzzerTestOneInput, otherwise a function registered
// under `name` for fuzz_replay (the corpus smoke run of the default test suite). A body returns 0; hgs::Error is
// the expected outcome for bad input and is caught by the body; anything else escaping it is a finding.
#pragma once
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <string_view>
#include <vector>

namespace hgs::fuzz {

using Harness = int (*)(const uint8_t* data, size_t size);
std::map<std::string, Harness>& registry();
struct Registration {
  Registration(const char* name, Harness h) { registry()[name] = h; }
};

// A fresh folder of this process for scratch files, on tmpfs (/dev/shm) when there is one; removed at exit.
// `sub` names a sub-folder (emptied on every call).
std::filesystem::path scratch(const std::string& sub);
// Writes bytes to `path` (atomic), creating its folder.
void put_file(const std::filesystem::path& path, std::string_view bytes);
// Splits the input at kSplit into exactly `n` parts (missing parts are empty, extra separators stay in the last).
inline constexpr std::string_view kSplit = "\n#HGS-FUZZ-SPLIT#\n";
std::vector<std::string_view> split(const uint8_t* data, size_t size, size_t n);
// A tiny synthetic scene (hgs synth: 4 views of 32x24, 3 objects, 200 points, feature dim 8, no noise), written
// once per process into the scratch area and reused.
const std::filesystem::path& tiny_scene();
// A scene skeleton for the parsers of scene files: the tiny scene's COLMAP model and images (hard links into a
// fresh folder `sub`), without masks/, features/ and text_embeddings.json.
std::filesystem::path scene_skeleton(const std::string& sub);

}  // namespace hgs::fuzz

#ifdef HGS_LIBFUZZER
#define HGS_FUZZ_TARGET(name) extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
#else
#define HGS_FUZZ_TARGET(name)                                                             \
  static int hgs_fuzz_##name(const uint8_t* data, size_t size);                           \
  static ::hgs::fuzz::Registration hgs_fuzz_registration_##name(#name, &hgs_fuzz_##name); \
  static int hgs_fuzz_##name(const uint8_t* data, size_t size)
#endif
