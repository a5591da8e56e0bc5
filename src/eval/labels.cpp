// Label loaders. Polygon fill as LangSplat's polygon_to_mask does it, cv2.fillPoly(mask, [np.int32(points)], 1)
// (LINE_8, shift 0), reproduced rule for rule (fill_polygon):
//  1. vertices truncated toward zero to integers (numpy's float -> int32 cast);
//  2. every edge drawn as OpenCV's 8-connected Bresenham line (boundary pixels are inside);
//  3. scanlines: a non-horizontal edge is active on rows [y_top, y_bottom); its crossing is kept in 16.16 fixed
//     point, starting at the upper vertex and stepping by ((x1 - x0) << 16) / (y1 - y0) (truncated) per row;
//     the sorted crossings are paired (even-odd) and each pair fills ceil(left) .. floor(right), inclusive.
// Deviation: OpenCV clips a line that leaves the image before stepping it, which can move its in-image pixels by
// one; here the whole line is stepped and out-of-image pixels are dropped. Coordinates are clamped to +-2^20.
#include "eval/labels.h"

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <map>
#include <nlohmann/json.hpp>
#include <set>

#include "core/error.h"
#include "core/fs.h"
#include "core/image.h"
#include "core/json_file.h"

namespace hgs::eval {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

// OpenCV's LineIterator (8-connected, left to right) from (x0, y0) to (x1, y1); pixels outside are dropped.
void draw_line(int64_t x0, int64_t y0, int64_t x1, int64_t y1, int width, int height, Mask& mask) {
  if (x1 < x0) std::swap(x0, x1), std::swap(y0, y1);
  const int64_t ax = x1 - x0, ay = std::abs(y1 - y0), sy = y1 < y0 ? -1 : 1;
  const bool y_major = ay > ax;
  const int64_t major = y_major ? ay : ax, minor = y_major ? ax : ay;
  int64_t err = major - 2 * minor, x = x0, y = y0;
  for (int64_t i = 0; i <= major; ++i) {
    if (x >= 0 && x < width && y >= 0 && y < height) mask[size_t(y) * width + size_t(x)] = 1;
    const bool step_minor = err < 0;
    err += -2 * minor + (step_minor ? 2 * major : 0);
    if (y_major) {
      y += sy;
      if (step_minor) ++x;
    } else {
      ++x;
      if (step_minor) y += sy;
    }
  }
}

}  // namespace

void fill_polygon(const std::vector<Point2>& poly, int width, int height, Mask& mask) {
  if (mask.size() != size_t(width) * height)
    fail("eval: polygon target mask holds {} pixels, expected {}x{}", mask.size(), width, height);
  const size_t n = poly.size();
  if (n == 0) return;
  constexpr double kLimit = 1 << 20;
  std::vector<std::array<int64_t, 2>> v(n);
  for (size_t i = 0; i < n; ++i)
    for (int c = 0; c < 2; ++c) {
      const double x = poly[i][c];
      v[i][c] = std::isnan(x) ? 0 : static_cast<int64_t>(std::clamp(x, -kLimit, kLimit));  // truncates toward 0
    }
  struct Edge {
    int64_t y0, y1, x, dx;
  };  // x: 16.16 fixed point at row y0
  std::vector<Edge> edges;
  int64_t ymin = v[0][1], ymax = v[0][1];
  for (size_t i = 0; i < n; ++i) {
    const auto& a = v[(i + n - 1) % n];
    const auto& b = v[i];
    draw_line(a[0], a[1], b[0], b[1], width, height, mask);
    ymin = std::min(ymin, b[1]);
    ymax = std::max(ymax, b[1]);
    if (a[1] == b[1]) continue;
    const auto& top = a[1] < b[1] ? a : b;
    const auto& bottom = a[1] < b[1] ? b : a;
    edges.push_back({top[1], bottom[1], top[0] * 65536, (b[0] - a[0]) * 65536 / (b[1] - a[1])});
  }
  std::vector<int64_t> xs;
  for (int64_t y = std::max<int64_t>(ymin, 0); y < std::min<int64_t>(ymax, height); ++y) {
    xs.clear();
    for (const Edge& e : edges)
      if (e.y0 <= y && y < e.y1) xs.push_back(e.x + (y - e.y0) * e.dx);
    std::sort(xs.begin(), xs.end());
    uint8_t* row = &mask[size_t(y) * width];
    for (size_t k = 0; k + 1 < xs.size(); k += 2) {
      // Arithmetic shifts: floor division by 65536 for negative crossings too.
      const int64_t x0 = std::max<int64_t>((xs[k] + 65535) >> 16, 0);
      const int64_t x1 = std::min<int64_t>(xs[k + 1] >> 16, width - 1);
      for (int64_t x = x0; x <= x1; ++x) row[x] = 1;
    }
  }
}

Mask rasterize_polygon(const std::vector<Point2>& poly, int width, int height) {
  Mask m(size_t(width) * height, 0);
  fill_polygon(poly, width, height, m);
  return m;
}

bool BBox::contains_pixel(int x, int y) const {
  // LangSplat's lerf_localization compares the integer pixel index with the box corners.
  return x >= x1 && x <= x2 && y >= y1 && y <= y2;
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

constexpr size_t kMaxMaskBytes = size_t(1) << 30;  // all category masks of one LERF-OVS frame together

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
      for (int k = 0; k < 4; ++k)
        b[k] = number(bb[k / 2][k % 2], file, fmt::format("{}.bbox[{}][{}]", where, k / 2, k % 2));
    } else {
      fail("{}: {} (\"{}\"): bbox must be [x1, y1, x2, y2] or [[x1, y1], [x2, y2]]", file.string(), where, cat);
    }
    BBox box;
    box.x1 = std::min(b[0], b[2]) * inv;
    box.x2 = std::max(b[0], b[2]) * inv;
    box.y1 = std::min(b[1], b[3]) * inv;
    box.y2 = std::max(b[1], b[3]) * inv;
    if (!ob.contains("segmentation")) fail("{}: {} (\"{}\"): missing key \"segmentation\"", file.string(), where, cat);
    const json& seg = ob["segmentation"];
    if (!seg.is_array())
      fail("{}: {} (\"{}\"): segmentation must be a list of [x, y] points", file.string(), where, cat);
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
      // Every category holds a full-size mask: their total is bounded before allocating another.
      if ((L.categories.size() + 1) * (size_t(L.width) * L.height) > kMaxMaskBytes)
        fail("{}: {} categories of {}x{} masks exceed {} MiB", file.string(), L.categories.size() + 1, L.width,
             L.height, kMaxMaskBytes >> 20);
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
      // Each class names a file <class>.png: it must be a name the file system can hold, printable on one line.
      if (c.size() > 200)
        fail("{}: line {}: class name of {} bytes is too long (at most 200)", cfile.string(), line, c.size());
      if (std::any_of(c.begin(), c.end(), [](char ch) { return static_cast<unsigned char>(ch) < 0x20 || ch == 0x7f; }))
        fail("{}: line {}: class name contains control characters", cfile.string(), line);
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
      fail("{}: folders \"{}\" and \"{}\" both name view {}", L.dir.string(), it->second.filename().string(), name,
           idx);
  }
  if (views.empty()) fail("{}: no labelled views (numbered sub-folders)", L.dir.string());
  for (auto& [idx, p] : views) L.views.push_back({idx, p});
  return L;
}

OvsViewLabels load_3dovs_view(const OvsLabelSet& labels, size_t i, int expect_width, int expect_height, int downscale) {
  if (downscale < 1) fail("{}: downscale factor must be >= 1, got {}", labels.dir.string(), downscale);
  if (i >= labels.views.size())
    fail("{}: view {} out of range ({} labelled views)", labels.dir.string(), i, labels.views.size());
  const auto& v = labels.views[i];
  OvsViewLabels out;
  out.index = v.index;
  int full_w = 0, full_h = 0;  // size of the first class PNG
  for (auto& c : labels.classes) {
    const fs::path p = v.dir / (c + ".png");
    std::error_code ec;
    if (!fs::is_regular_file(p, ec))
      fail("{}: missing class mask for \"{}\"{}", p.string(), c, ec ? " (" + ec.message() + ")" : "");
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
