// Label loaders. Polygon fill: for each pixel row, intersect the horizontal line through the row's pixel
// centres with every edge (half-open in y), sort the crossings and fill the pixel centres lying in
// [c0, c1), [c2, c3), ... — the even-odd rule, so self-overlapping parts cancel.
#include "eval/labels.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <map>
#include <nlohmann/json.hpp>
#include <set>

#include "core/error.h"
#include "core/fs.h"
#include "core/image.h"
#include "eval/json_file.h"

namespace hgs::eval {

namespace fs = std::filesystem;
using nlohmann::json;

void fill_polygon(const std::vector<Point2>& poly, int width, int height, Mask& mask) {
  if (mask.size() != size_t(width) * height)
    fail("eval: polygon target mask holds {} pixels, expected {}x{}", mask.size(), width, height);
  const size_t n = poly.size();
  if (n < 3) return;
  double ymin = poly[0][1], ymax = poly[0][1];
  for (auto& p : poly) { ymin = std::min(ymin, p[1]); ymax = std::max(ymax, p[1]); }
  const int r0 = static_cast<int>(std::clamp(std::floor(ymin - 0.5), 0.0, double(height)));
  const int r1 = static_cast<int>(std::clamp(std::ceil(ymax), -1.0, double(height - 1)));
  std::vector<double> xs;
  for (int y = r0; y <= r1; ++y) {
    const double yc = y + 0.5;
    xs.clear();
    for (size_t i = 0; i < n; ++i) {
      const Point2& a = poly[i];
      const Point2& b = poly[(i + 1) % n];
      if ((a[1] <= yc && yc < b[1]) || (b[1] <= yc && yc < a[1]))
        xs.push_back(a[0] + (yc - a[1]) * (b[0] - a[0]) / (b[1] - a[1]));
    }
    std::sort(xs.begin(), xs.end());
    uint8_t* row = &mask[size_t(y) * width];
    for (size_t k = 0; k + 1 < xs.size(); k += 2) {
      // Pixel x is inside iff xs[k] <= x + 0.5 < xs[k+1].
      const double lo = std::ceil(xs[k] - 0.5), hi = std::ceil(xs[k + 1] - 0.5) - 1;
      const int x0 = static_cast<int>(std::clamp(lo, 0.0, double(width)));
      const int x1 = static_cast<int>(std::clamp(hi, -1.0, double(width - 1)));
      for (int x = x0; x <= x1; ++x) row[x] = 1;
    }
  }
}

Mask rasterize_polygon(const std::vector<Point2>& poly, int width, int height) {
  Mask m(size_t(width) * height, 0);
  fill_polygon(poly, width, height, m);
  return m;
}

bool BBox::contains_pixel(int x, int y) const {
  const double cx = x + 0.5, cy = y + 0.5;
  return cx >= x1 && cx <= x2 && cy >= y1 && cy <= y2;
}

const LerfCategory* LerfFrameLabels::find(const std::string& name) const {
  for (auto& c : categories)
    if (c.name == name) return &c;
  return nullptr;
}

namespace {

double number(const json& v, const fs::path& file, const std::string& where) {
  if (!v.is_number()) fail("{}: {} must be a number, found {}", file.string(), where, v.dump());
  const double d = v.get<double>();
  if (!std::isfinite(d)) fail("{}: {} is not finite", file.string(), where);
  return d;
}

int positive_int(const json& obj, const char* key, const fs::path& file) {
  if (!obj.contains(key)) fail("{}: missing key info.{}", file.string(), key);
  const json& v = obj[key];
  if (!v.is_number_integer() || v.get<long long>() <= 0 || v.get<long long>() > 1000000)
    fail("{}: info.{} must be a positive integer, found {}", file.string(), key, v.dump());
  return static_cast<int>(v.get<long long>());
}

}  // namespace

LerfFrameLabels load_lerf_frame(const fs::path& file, int expect_width, int expect_height, int downscale) {
  if (downscale < 1) fail("{}: downscale factor must be >= 1, got {}", file.string(), downscale);
  const double inv = 1.0 / downscale;
  const json j = read_json_file(file);
  if (!j.is_object()) fail("{}: expected a JSON object with keys \"info\" and \"objects\"", file.string());
  if (!j.contains("info") || !j["info"].is_object()) fail("{}: missing key \"info\" (an object)", file.string());
  if (!j.contains("objects") || !j["objects"].is_array()) fail("{}: missing key \"objects\" (an array)", file.string());
  const json& info = j["info"];
  LerfFrameLabels L;
  L.file = file;
  L.stem = file.stem().string();
  if (!info.contains("name") || !info["name"].is_string()) fail("{}: missing key info.name (a string)", file.string());
  L.image_name = info["name"].get<std::string>();
  L.width = positive_int(info, "width", file);
  L.height = positive_int(info, "height", file);
  if (downscale > 1) {
    if (L.width < downscale || L.height < downscale)
      fail("{}: label size {}x{} is smaller than the downscale factor {}", file.string(), L.width, L.height, downscale);
    L.width /= downscale;
    L.height /= downscale;
  }
  if ((expect_width > 0 || expect_height > 0) && (L.width != expect_width || L.height != expect_height))
    fail("{}: label size {}x{} does not match the image size {}x{}", file.string(), L.width, L.height, expect_width,
         expect_height);
  std::map<std::string, size_t> index;
  const json& objs = j["objects"];
  for (size_t o = 0; o < objs.size(); ++o) {
    const json& ob = objs[o];
    const std::string where = fmt::format("objects[{}]", o);
    if (!ob.is_object()) fail("{}: {} must be an object", file.string(), where);
    if (!ob.contains("category") || !ob["category"].is_string())
      fail("{}: {}: missing key \"category\" (a string)", file.string(), where);
    const std::string cat = ob["category"].get<std::string>();
    if (cat.empty()) fail("{}: {}: empty category name", file.string(), where);
    if (!ob.contains("bbox")) fail("{}: {} (\"{}\"): missing key \"bbox\"", file.string(), where, cat);
    const json& bb = ob["bbox"];
    double b[4];
    if (bb.is_array() && bb.size() == 4) {
      for (int k = 0; k < 4; ++k) b[k] = number(bb[k], file, fmt::format("{}.bbox[{}]", where, k));
    } else if (bb.is_array() && bb.size() == 2 && bb[0].is_array() && bb[0].size() == 2 && bb[1].is_array() &&
               bb[1].size() == 2) {  // [[x1, y1], [x2, y2]]
      for (int k = 0; k < 4; ++k) b[k] = number(bb[k / 2][k % 2], file, fmt::format("{}.bbox[{}][{}]", where, k / 2, k % 2));
    } else {
      fail("{}: {} (\"{}\"): bbox must be [x1, y1, x2, y2] or [[x1, y1], [x2, y2]]", file.string(), where, cat);
    }
    BBox box;
    box.x1 = std::min(b[0], b[2]) * inv; box.x2 = std::max(b[0], b[2]) * inv;
    box.y1 = std::min(b[1], b[3]) * inv; box.y2 = std::max(b[1], b[3]) * inv;
    if (!ob.contains("segmentation")) fail("{}: {} (\"{}\"): missing key \"segmentation\"", file.string(), where, cat);
    const json& seg = ob["segmentation"];
    if (!seg.is_array()) fail("{}: {} (\"{}\"): segmentation must be a list of [x, y] points", file.string(), where, cat);
    // One polygon [[x, y], ...] or several [[[x, y], ...], ...].
    const bool multi = !seg.empty() && seg[0].is_array() && !seg[0].empty() && seg[0][0].is_array();
    std::vector<std::vector<Point2>> polys;
    for (size_t pi = 0; pi < (multi ? seg.size() : 1); ++pi) {
      const json& pts = multi ? seg[pi] : seg;
      const std::string pwhere = multi ? fmt::format("{}.segmentation[{}]", where, pi) : where + ".segmentation";
      if (!pts.is_array()) fail("{}: {} must be a list of [x, y] points", file.string(), pwhere);
      if (pts.size() < 3)
        fail("{}: {} (\"{}\"): polygon has {} point(s), need at least 3", file.string(), where, cat, pts.size());
      std::vector<Point2> poly;
      poly.reserve(pts.size());
      for (size_t k = 0; k < pts.size(); ++k) {
        const json& p = pts[k];
        const std::string pw = fmt::format("{}[{}]", pwhere, k);
        if (!p.is_array() || p.size() != 2) fail("{}: {} must be an [x, y] pair", file.string(), pw);
        poly.push_back({number(p[0], file, pw + "[0]") * inv, number(p[1], file, pw + "[1]") * inv});
      }
      polys.push_back(std::move(poly));
    }
    auto it = index.find(cat);
    if (it == index.end()) {
      it = index.emplace(cat, L.categories.size()).first;
      LerfCategory c;
      c.name = cat;
      c.mask.assign(size_t(L.width) * L.height, 0);
      L.categories.push_back(std::move(c));
    }
    LerfCategory& c = L.categories[it->second];
    for (auto& poly : polys) {
      fill_polygon(poly, L.width, L.height, c.mask);  // several polygons of one object are OR-ed as well
      c.polygons.push_back(std::move(poly));
    }
    c.bboxes.push_back(box);
  }
  return L;
}

std::vector<LerfFrameLabels> load_lerf_labels(const fs::path& scene, int expect_width, int expect_height,
                                              int downscale) {
  const fs::path dir = scene / "label";
  if (!fs::is_directory(dir)) fail("{}: no LERF-OVS label folder", dir.string());
  std::vector<fs::path> files;
  for (auto& e : fs::directory_iterator(dir))
    if (e.is_regular_file() && e.path().extension() == ".json") files.push_back(e.path());
  if (files.empty()) fail("{}: no LERF-OVS label files (*.json)", dir.string());
  std::sort(files.begin(), files.end());
  std::vector<LerfFrameLabels> out;
  for (auto& f : files) out.push_back(load_lerf_frame(f, expect_width, expect_height, downscale));
  return out;
}

namespace {

std::string trim(const std::string& s) {
  size_t a = 0, b = s.size();
  while (a < b && std::isspace(static_cast<unsigned char>(s[a]))) ++a;
  while (b > a && std::isspace(static_cast<unsigned char>(s[b - 1]))) --b;
  return s.substr(a, b - a);
}

}  // namespace

OvsLabelSet open_3dovs_labels(const fs::path& scene) {
  OvsLabelSet L;
  L.dir = scene / "segmentations";
  if (!fs::is_directory(L.dir)) fail("{}: no 3D-OVS segmentation folder", L.dir.string());
  const fs::path cfile = L.dir / "classes.txt";
  if (!fs::is_regular_file(cfile)) fail("{}: file not found (3D-OVS class list)", cfile.string());
  const std::string text = read_file_text(cfile);
  std::set<std::string> seen;
  size_t start = 0, line = 0;
  while (start <= text.size()) {
    size_t end = text.find('\n', start);
    if (end == std::string::npos) end = text.size();
    ++line;
    std::string c = trim(text.substr(start, end - start));
    if (!c.empty()) {
      if (c.find('/') != std::string::npos || c.find('\\') != std::string::npos)
        fail("{}: line {}: class name \"{}\" contains a path separator", cfile.string(), line, c);
      if (!seen.insert(c).second) fail("{}: line {}: duplicate class \"{}\"", cfile.string(), line, c);
      L.classes.push_back(c);
    }
    start = end + 1;
  }
  if (L.classes.empty()) fail("{}: no class names", cfile.string());
  std::sort(L.classes.begin(), L.classes.end());
  std::map<int, fs::path> views;
  for (auto& e : fs::directory_iterator(L.dir)) {
    if (!e.is_directory()) continue;
    const std::string name = e.path().filename().string();
    if (name.empty() || name.size() > 9 ||
        !std::all_of(name.begin(), name.end(), [](char ch) { return std::isdigit(static_cast<unsigned char>(ch)); }))
      continue;
    const int idx = std::stoi(name);
    auto [it, fresh] = views.emplace(idx, e.path());
    if (!fresh)
      fail("{}: folders \"{}\" and \"{}\" both name view {}", L.dir.string(), it->second.filename().string(), name, idx);
  }
  if (views.empty()) fail("{}: no labelled views (numbered sub-folders)", L.dir.string());
  for (auto& [idx, p] : views) L.views.push_back({idx, p});
  return L;
}

OvsViewLabels load_3dovs_view(const OvsLabelSet& labels, size_t i, int expect_width, int expect_height,
                              int downscale) {
  if (downscale < 1) fail("{}: downscale factor must be >= 1, got {}", labels.dir.string(), downscale);
  if (i >= labels.views.size()) fail("{}: view {} out of range ({} labelled views)", labels.dir.string(), i, labels.views.size());
  const auto& v = labels.views[i];
  OvsViewLabels out;
  out.index = v.index;
  int full_w = 0, full_h = 0;  // size of the first class PNG
  for (auto& c : labels.classes) {
    const fs::path p = v.dir / (c + ".png");
    if (!fs::is_regular_file(p)) fail("{}: missing class mask for \"{}\"", p.string(), c);
    const Image img = load_image(p, 1);
    if (out.masks.empty()) {
      full_w = img.width;
      full_h = img.height;
      if (full_w < downscale || full_h < downscale)
        fail("{}: mask size {}x{} is smaller than the downscale factor {}", p.string(), full_w, full_h, downscale);
      out.width = full_w / downscale;
      out.height = full_h / downscale;
      if ((expect_width > 0 || expect_height > 0) && (out.width != expect_width || out.height != expect_height))
        fail("{}: mask size {}x{}{} does not match the image size {}x{}", p.string(), out.width, out.height,
             downscale > 1 ? fmt::format(" (downscaled by {})", downscale) : "", expect_width, expect_height);
    } else if (img.width != full_w || img.height != full_h) {
      fail("{}: mask size {}x{} does not match the view's other masks {}x{}", p.string(), img.width, img.height, full_w,
           full_h);
    }
    Mask m(size_t(out.width) * out.height);
    const int off = downscale / 2;
    for (int y = 0; y < out.height; ++y)
      for (int x = 0; x < out.width; ++x)
        m[size_t(y) * out.width + x] =
            img.px[size_t(y * downscale + off) * full_w + x * downscale + off] * 255.f >= 254.5f ? 1 : 0;
    out.masks.push_back(std::move(m));
  }
  return out;
}

}  // namespace hgs::eval
