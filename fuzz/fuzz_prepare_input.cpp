// The input stage of `hgs prepare` (prepare::import_photos, what `hgs prepare DIR` runs first): one photo with a
// fuzzed name and fuzzed bytes (image headers, truncations, EXIF) in a folder. Input = NAME kSplit BYTES. The name
// is made a legal file name (no '/' or NUL, at most 255 bytes) but keeps every other byte: backslashes, tabs,
// newlines, control characters, invalid UTF-8, a leading dot or dash. Checked: with skip_bad the stage either
// fails with hgs::Error or accounts for the file exactly once (an image, not an image, or bad); every image it
// reports exists in the output folder with the reported size, within max_size; the EXIF helpers stay in range.
#include <algorithm>
#include <filesystem>
#include <string>

#include "core/error.h"
#include "fuzz.h"
#include "prepare/exif.h"
#include "prepare/photos.h"

namespace fs = std::filesystem;

namespace {
std::string legal_name(std::string_view raw) {
  std::string n(raw.substr(0, 255));
  for (char& c : n)
    if (c == '/' || c == '\0') c = '_';
  if (n.empty() || n == "." || n == "..") n = "photo.jpg";
  return n;
}
}  // namespace

HGS_FUZZ_TARGET(prepare_input) {
  const auto parts = hgs::fuzz::split(data, size, 2);
  const auto* bytes = reinterpret_cast<const uint8_t*>(parts[1].data());
  const int orientation = hgs::prepare::exif_orientation(bytes, parts[1].size());
  if (orientation < 1 || orientation > 8) __builtin_trap();
  const auto app1 = hgs::prepare::upright_exif(bytes, parts[1].size(), 17, 9);
  if (!app1.empty() && (app1.size() > 65533 || !std::equal(app1.begin(), app1.begin() + 6, "Exif\0\0")))
    __builtin_trap();

  const auto root = hgs::fuzz::scratch("prepare_input");
  const fs::path in = root / "photos", out = root / "scene" / "prepare" / "input";
  fs::create_directories(in);
  hgs::fuzz::put_file(in / legal_name(parts[0]), parts[1]);
  hgs::prepare::InputOptions opt;
  opt.max_size = 48;  // small outputs: the fuzzer's time goes to the parsers, not to resizing
  opt.progress = false;
  for (bool skip_bad : {true, false}) {
    opt.skip_bad = skip_bad;
    try {
      const auto report = hgs::prepare::import_photos(in, out, opt);
      if (report.images.size() + report.not_images.size() + report.bad.size() != 1) __builtin_trap();
      for (const auto& img : report.images) {
        if (img.width < 1 || img.height < 1 || std::max(img.width, img.height) > opt.max_size) __builtin_trap();
        if (!fs::is_regular_file(out / img.name)) __builtin_trap();
      }
    } catch (const hgs::Error&) {
    }
  }
  return 0;
}
