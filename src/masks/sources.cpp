// SAM JSON (COCO RLE), amg.py PNG folders and SAM2 label PNGs, read into source masks or label maps.
#include "masks/sources.h"

#include <nlohmann/json.hpp>
#include <sstream>

#include "core/error.h"
#include "core/fs.h"
#include "core/json_file.h"
#include "masks/png_index.h"

namespace hgs::masks {
namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

double optional_number(const json& m, const char* key) {
  auto it = m.find(key);
  return (it != m.end() && it->is_number()) ? it->get<double>() : -1.0;
}

std::vector<std::string> split_csv_line(const std::string& line) {
  std::vector<std::string> out;
  std::string cur;
  for (char c : line) {
    if (c == ',') {
      out.push_back(cur);
      cur.clear();
    } else if (c != '\r' && c != '"') cur.push_back(c);
  }
  out.push_back(cur);
  for (auto& s : out) {
    while (!s.empty() && s.front() == ' ') s.erase(s.begin());
    while (!s.empty() && s.back() == ' ') s.pop_back();
  }
  return out;
}

}  // namespace

std::vector<SourceMask> read_sam_json(const fs::path& file, int width, int height) {
  const std::string name = file.string();
  const json j = read_json_file(file);
  if (!j.is_array()) fail("{}: expected a JSON list of masks (SAM automatic mask generator output)", name);
  std::vector<SourceMask> out;
  for (size_t i = 0; i < j.size(); ++i) {
    const json& m = j[i];
    const std::string where = fmt::format("{}: mask {}", name, i);
    if (!m.is_object() || !m.contains("segmentation")) fail("{} has no 'segmentation'", where);
    const json& seg = m["segmentation"];
    if (!seg.is_object() || !seg.contains("size") || !seg.contains("counts"))
      fail("{}: 'segmentation' is not COCO RLE {{size: [h, w], counts}}", where);
    const json& sz = seg["size"];
    if (!sz.is_array() || sz.size() != 2 || !sz[0].is_number_integer() || !sz[1].is_number_integer())
      fail("{}: RLE 'size' must be [h, w]", where);
    SourceMask s;
    s.rle.height = sz[0].get<int>();
    s.rle.width = sz[1].get<int>();
    if (s.rle.height != height || s.rle.width != width)
      fail("{}: RLE size {}x{} (h x w) does not match the image's {}x{}", where, s.rle.height, s.rle.width, height,
           width);
    const json& c = seg["counts"];
    if (c.is_string()) {
      s.rle.counts = rle_counts_from_string(c.get<std::string>(), where);
    } else if (c.is_array()) {
      for (auto& v : c) {
        if (!v.is_number_integer() || v.get<int64_t>() < 0 || v.get<int64_t>() > int64_t(UINT32_MAX))
          fail("{}: RLE 'counts' must hold non-negative integers", where);
        s.rle.counts.push_back(uint32_t(v.get<int64_t>()));
      }
    } else {
      fail("{}: RLE 'counts' must be a string or a list of integers", where);
    }
    rle_check(s.rle, where);  // the runs must cover exactly h x w pixels
    s.predicted_iou = optional_number(m, "predicted_iou");
    s.stability_score = optional_number(m, "stability_score");
    s.source = fmt::format("{}[{}]", file.filename().string(), i);
    out.push_back(std::move(s));
  }
  return out;
}

std::vector<SourceMask> read_sam_png_folder(const fs::path& folder, int width, int height) {
  const fs::path csv = folder / "metadata.csv";
  std::istringstream in(read_file_text(csv));
  std::string line;
  if (!std::getline(in, line)) fail("{}: empty file (expected the header id,area,bbox_x0,...)", csv.string());
  const auto header = split_csv_line(line);
  auto column = [&](const std::string& key) {
    for (size_t k = 0; k < header.size(); ++k)
      if (header[k] == key) return int(k);
    return -1;
  };
  const int c_id = column("id"), c_iou = column("predicted_iou"), c_stab = column("stability_score");
  if (c_id < 0) fail("{}: header has no 'id' column", csv.string());
  std::vector<SourceMask> out;
  int row = 1;
  while (std::getline(in, line)) {
    ++row;
    if (line.empty() || line == "\r") continue;
    const auto f = split_csv_line(line);
    if (f.size() != header.size())
      fail("{}: line {} has {} fields, the header {}", csv.string(), row, f.size(), header.size());
    auto number = [&](int col) -> double {
      if (col < 0) return -1;
      try {
        size_t used = 0;
        double v = std::stod(f[col], &used);
        if (used != f[col].size()) throw std::invalid_argument("");
        return v;
      } catch (...) {
        fail("{}: line {}: '{}' is not a number", csv.string(), row, f[col]);
      }
    };
    const fs::path png = folder / (f[c_id] + ".png");
    if (!fs::exists(png)) fail("{}: line {}: mask file {} not found", csv.string(), row, png.string());
    LabelMap m = load_index_png(png);
    if (m.width != width || m.height != height)
      fail("{}: mask is {}x{} but the image is {}x{}", png.string(), m.width, m.height, width, height);
    std::vector<uint8_t> bin(m.v.size());
    for (size_t p = 0; p < bin.size(); ++p) bin[p] = m.v[p] != 0;
    SourceMask s;
    s.rle = rle_encode(bin, width, height);
    s.predicted_iou = number(c_iou);
    s.stability_score = number(c_stab);
    s.source = fmt::format("{}/{}.png", folder.filename().string(), f[c_id]);
    out.push_back(std::move(s));
  }
  return out;
}

LabelMap read_sam2_png(const fs::path& file, int width, int height) {
  LabelMap m = load_index_png(file);
  if (m.width != width || m.height != height)
    fail("{}: label map is {}x{} but the image is {}x{}", file.string(), m.width, m.height, width, height);
  return m;
}

}  // namespace hgs::masks
