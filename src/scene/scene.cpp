// Scene loading (scene.h): the COLMAP model, the views with their image / mask / confidence / feature paths, the
// train/test split, object names and text embeddings; the per-view loaders of Scene.
#include "scene/scene.h"

#include <stb/stb_image_write.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>

#include "core/error.h"
#include "core/fs.h"
#include "core/json_file.h"
#include "core/npy.h"
#include "scene/colmap.h"

namespace hgs {
namespace fs = std::filesystem;
using json = nlohmann::json;

std::vector<int> Scene::train_indices() const {
  std::vector<int> r;
  for (auto& v : views)
    if (!v.is_test) r.push_back(v.index);
  return r;
}
std::vector<int> Scene::test_indices() const {
  std::vector<int> r;
  for (auto& v : views)
    if (v.is_test) r.push_back(v.index);
  return r;
}
bool Scene::has_masks() const {
  return std::any_of(views.begin(), views.end(), [](const View& v) { return v.mask_path.has_value(); });
}
bool Scene::has_features() const {
  return std::any_of(views.begin(), views.end(), [](const View& v) { return v.feature_path.has_value(); });
}

namespace {

std::string strip_ext(const std::string& name) {
  fs::path p(name);
  return (p.parent_path() / p.stem()).generic_string();
}

// fs::exists without its filesystem_error: a path the system cannot look up (a name too long, made from a COLMAP
// image name) is a one-line hgs::Error naming it.
bool path_exists(const fs::path& p) {
  std::error_code ec;
  const bool e = fs::exists(p, ec);
  if (ec) fail("{}: cannot access ({})", p.string(), ec.message());
  return e;
}

constexpr uint64_t kMaxSide = 1 << 16;  // largest camera width or height accepted (pixels)

// One view of COLMAP image `im` at downscale F, with the paths of its image (images_F/ when there), mask,
// confidence and features. Sizes and poses from the file are checked before anything is sized or rendered by them.
View make_view(const fs::path& root, const fs::path& sparse, const ColmapModel& m, const ColmapImage& im, int F) {
  const fs::path images_dir = root / "images", scaled_dir = root / fmt::format("images_{}", F);
  View v;
  v.colmap_id = im.id;
  v.name = im.name;
  v.stem = strip_ext(im.name);
  const ColmapCamera& cam = m.cameras.at(im.camera_id);
  double fx, fy, cx, cy;
  require_pinhole(cam, (sparse / "cameras").string(), fx, fy, cx, cy);
  if (cam.width < 1 || cam.height < 1 || cam.width > kMaxSide || cam.height > kMaxSide)
    fail("{}: camera {} is {}x{} pixels; expected 1..{} a side", (sparse / "cameras").string(), cam.id, cam.width,
         cam.height, kMaxSide);
  if (!(std::isfinite(fx) && std::isfinite(fy) && fx > 0 && fy > 0 && std::isfinite(cx) && std::isfinite(cy)))
    fail("{}: camera {} has invalid intrinsics (fx {}, fy {}, cx {}, cy {})", (sparse / "cameras").string(), cam.id, fx,
         fy, cx, cy);
  if (!im.qvec.allFinite() || !im.tvec.allFinite() || im.qvec.norm() < 1e-12)
    fail("{}: image '{}' has an invalid pose (non-finite or zero quaternion)", (sparse / "images").string(), im.name);
  v.image_path = images_dir / im.name;
  if (!path_exists(v.image_path))
    fail("{}: image '{}' is listed in the COLMAP model but missing", v.image_path.string(), im.name);
  // COLMAP puts the pixel-coordinate origin at the top-left corner of the top-left pixel, so an integer
  // downscale divides every intrinsic by F exactly.
  v.width = static_cast<int>(cam.width) / F;
  v.height = static_cast<int>(cam.height) / F;
  v.fx = fx / F;
  v.fy = fy / F;
  v.cx = cx / F;
  v.cy = cy / F;
  if (F > 1 && path_exists(scaled_dir / im.name)) v.image_path = scaled_dir / im.name;
  v.R = qvec_to_rotmat(im.qvec);
  v.t = im.tvec;
  fs::path mp = root / "masks" / (v.stem + ".png");
  if (path_exists(mp)) v.mask_path = mp;
  fs::path cp = root / "masks" / (v.stem + ".conf.npy");
  if (path_exists(cp)) v.conf_path = cp;
  fs::path fp = root / "features" / (v.stem + ".npy");
  if (path_exists(fp)) v.feature_path = fp;
  return v;
}

// Train/test split: test.txt (image names or stems, one a line), else every 8th view (LLFF).
void split_views(Scene& s) {
  fs::path test_txt = s.root / "test.txt";
  if (path_exists(test_txt)) {
    std::istringstream in(read_file_text(test_txt));
    std::set<std::string> names;
    std::string line;
    while (std::getline(in, line)) {
      while (!line.empty() && (line.back() == '\r' || line.back() == ' ')) line.pop_back();
      if (!line.empty()) names.insert(line);
    }
    int found = 0;
    for (auto& v : s.views)
      if (names.count(v.name) || names.count(v.stem)) {
        v.is_test = true;
        ++found;
      }
    if (found != static_cast<int>(names.size()))
      fail("{}: {} of the {} listed test images are not in the COLMAP model", test_txt.string(), names.size() - found,
           names.size());
    s.split_source = "test.txt";
  } else {
    for (auto& v : s.views) v.is_test = (v.index % 8 == 0);
    s.split_source = "every 8th view (LLFF)";
  }
}

void load_points(Scene& s, const ColmapModel& m, const fs::path& sparse) {
  s.points.reserve(m.points.size());
  for (auto& p : m.points) {
    if (!p.xyz.cast<float>().allFinite())
      fail("{}: point {} has non-finite coordinates", (sparse / "points3D").string(), p.id);
    s.points.emplace_back(p.xyz.cast<float>());
    s.point_colors.emplace_back(p.rgb[0] / 255.f, p.rgb[1] / 255.f, p.rgb[2] / 255.f);
  }
}

// masks/objects.json: {"1": "name", ...}.
std::map<int, std::string> read_object_names(const fs::path& objects) {
  std::map<int, std::string> names;
  json j = read_json_file(objects);
  if (!j.is_object()) fail("{}: expected an object {{\"1\": \"name\", ...}}", objects.string());
  for (auto& [k, val] : j.items()) {
    int id;
    try {
      id = std::stoi(k);
    } catch (...) {
      fail("{}: key '{}' is not an object id", objects.string(), k);
    }
    if (!val.is_string()) fail("{}: name of object {} is not a string", objects.string(), k);
    names[id] = val.get<std::string>();
  }
  return names;
}

// text_embeddings.json: {"phrase": [D floats], ...}, every D the same.
std::map<std::string, std::vector<float>> read_text_embeddings(const fs::path& te) {
  std::map<std::string, std::vector<float>> out;
  json j = read_json_file(te);
  if (!j.is_object()) fail("{}: expected an object {{\"phrase\": [floats], ...}}", te.string());
  size_t dim = 0;
  for (auto& [k, val] : j.items()) {
    if (!val.is_array() || val.empty() ||
        !std::all_of(val.begin(), val.end(), [](const json& x) { return x.is_number(); }))
      fail("{}: embedding of '{}' is not an array of numbers", te.string(), k);
    std::vector<float> vec;
    vec.reserve(val.size());
    for (const json& x : val) {  // range-checked as double: a double -> float cast out of range is undefined
      const double d = x.get<double>();
      if (!(std::abs(d) <= std::numeric_limits<float>::max()))
        fail("{}: embedding of '{}' holds {}, not a finite float", te.string(), k, x.dump());
      vec.push_back(float(d));
    }
    if (dim && vec.size() != dim)
      fail("{}: embedding of '{}' has {} values, others have {}", te.string(), k, vec.size(), dim);
    dim = vec.size();
    out[k] = std::move(vec);
  }
  return out;
}

// Writes the downscaled copy of every image not read from images_F/ yet and points the view at it.
void cache_downscaled(Scene& s, const fs::path& scaled_dir) {
  for (auto& v : s.views) {
    if (v.image_path.parent_path() == scaled_dir / fs::path(v.name).parent_path()) continue;
    Image img = s.load_image(v.index);
    fs::path out = scaled_dir / v.name;
    std::string ext = out.extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), ::tolower);
    if (ext == ".png") {
      save_png(out, img);
    } else {
      std::vector<uint8_t> b(img.px.size());
      for (size_t i = 0; i < b.size(); ++i) b[i] = static_cast<uint8_t>(std::clamp(img.px[i], 0.f, 1.f) * 255.f + 0.5f);
      atomic_write(out, [&](const fs::path& tmp) {
        if (!stbi_write_jpg(tmp.c_str(), img.width, img.height, 3, b.data(), 95))
          fail("{}: cannot write", out.string());
      });
    }
    v.image_path = out;
  }
}

}  // namespace

Scene load_scene(const fs::path& root_in, const SceneOptions& opt) {
  Scene s;
  s.root = root_in;
  s.downscale = std::max(1, opt.downscale);
  if (!path_exists(s.root)) fail("{}: scene folder not found", s.root.string());
  if (!fs::is_directory(s.root)) fail("{}: not a folder", s.root.string());
  const fs::path sparse = colmap_model_dir(s.root);
  if (!fs::is_directory(s.root / "images")) fail("{}: images/ folder not found", s.root.string());
  ColmapModel m = read_colmap(sparse);
  if (m.images.empty()) fail("{}: the COLMAP model lists no images", sparse.string());

  for (auto& im : m.images) s.views.push_back(make_view(s.root, sparse, m, im, s.downscale));
  std::sort(s.views.begin(), s.views.end(), [](const View& a, const View& b) { return a.name < b.name; });
  for (size_t i = 0; i < s.views.size(); ++i) s.views[i].index = static_cast<int>(i);
  split_views(s);
  load_points(s, m, sparse);
  const fs::path objects = s.root / "masks" / "objects.json", te = s.root / "text_embeddings.json";
  if (path_exists(objects)) s.object_names = read_object_names(objects);
  if (path_exists(te)) s.text_embeddings = read_text_embeddings(te);
  if (opt.cache_downscaled && s.downscale > 1) cache_downscaled(s, s.root / fmt::format("images_{}", s.downscale));
  return s;
}

Image Scene::load_image(int vi) const {
  const View& v = views.at(vi);
  Image img = hgs::load_image(v.image_path, 3);
  if (img.width == v.width && img.height == v.height) return img;
  if (img.width / downscale == v.width && img.height / downscale == v.height) return downscale_area(img, downscale);
  fail("{}: image is {}x{} but the COLMAP camera says {}x{}", v.image_path.string(), img.width, img.height,
       v.width * downscale, v.height * downscale);
}

std::optional<LabelMap> Scene::load_mask(int vi) const {
  const View& v = views.at(vi);
  if (!v.mask_path) return std::nullopt;
  LabelMap m = load_label_png(*v.mask_path);
  if (m.width == v.width && m.height == v.height) return m;
  if (m.width / downscale == v.width && m.height / downscale == v.height) return downscale_labels(m, downscale);
  fail("{}: mask is {}x{} but its image is {}x{}", v.mask_path->string(), m.width, m.height, v.width * downscale,
       v.height * downscale);
}

std::optional<std::vector<float>> Scene::load_confidence(int vi) const {
  const View& v = views.at(vi);
  if (!v.conf_path) return std::nullopt;
  NpyArray a = read_npy(*v.conf_path);
  if (a.shape.size() != 2)
    fail("{}: confidence must be a 2-D [H, W] array, found {} dimensions", v.conf_path->string(), a.shape.size());
  if (a.dtype != DType::F32 && a.dtype != DType::F16)
    fail("{}: confidence must be float16 or float32", v.conf_path->string());
  int h = static_cast<int>(a.shape[0]), w = static_cast<int>(a.shape[1]);
  std::vector<float> c = a.to_float();
  if (w == v.width && h == v.height) return c;
  if (w / downscale == v.width && h / downscale == v.height) {
    Image im(w, h, 1);
    im.px = std::move(c);
    return downscale_area(im, downscale).px;
  }
  fail("{}: confidence is {}x{} but its image is {}x{}", v.conf_path->string(), w, h, v.width * downscale,
       v.height * downscale);
}

std::optional<std::vector<float>> Scene::load_features(int vi, int& dim) const {
  int h = 0, w = 0;
  auto f = load_feature_grid(vi, h, w, dim);
  if (!f) return std::nullopt;
  const View& v = views.at(vi);
  if (h == v.height && w == v.width) return f;
  return upsample_bilinear(f->data(), h, w, dim, v.height, v.width);
}

std::optional<std::vector<float>> Scene::load_feature_grid(int vi, int& h, int& w, int& dim) const {
  const View& v = views.at(vi);
  if (!v.feature_path) return std::nullopt;
  NpyArray a = read_npy(*v.feature_path);
  if (a.shape.size() != 3)
    fail("{}: features must be a 3-D [h, w, D] array, found {} dimensions", v.feature_path->string(), a.shape.size());
  if (a.dtype != DType::F32 && a.dtype != DType::F16)
    fail("{}: features must be float16 or float32", v.feature_path->string());
  h = static_cast<int>(a.shape[0]);
  w = static_cast<int>(a.shape[1]);
  dim = static_cast<int>(a.shape[2]);
  if (h == 0 || w == 0 || dim == 0) fail("{}: empty feature array", v.feature_path->string());
  return a.to_float();
}

int Scene::num_objects() const {
  if (num_objects_cache_ >= 0) return num_objects_cache_;
  int k = 0;
  for (auto& v : views) {
    if (!v.mask_path) continue;
    LabelMap m = load_label_png(*v.mask_path);
    for (uint16_t l : m.v) k = std::max<int>(k, l);
  }
  for (auto& [id, name] : object_names) k = std::max(k, id);
  num_objects_cache_ = k;
  return k;
}

std::vector<float> upsample_bilinear(const float* src, int h, int w, int d, int H, int W) {
  std::vector<float> out(size_t(H) * W * d);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x)
      bilinear_sample(bilinear_tap(src, h, w, d, H, W, x, y), d, out.data() + (size_t(y) * W + x) * d);
  return out;
}

float scene_extent(const Scene& scene, const std::vector<int>& views) {
  std::vector<int> idx = views;
  if (idx.empty())
    for (auto& v : scene.views) idx.push_back(v.index);
  if (idx.empty()) return 1.f;
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (int i : idx) c += scene.views[i].camera_center();
  c /= double(idx.size());
  double r = 0;
  for (int i : idx) r = std::max(r, (scene.views[i].camera_center() - c).norm());
  if (r <= 0) r = 1.0 / 1.1;  // a single camera: unit extent
  return float(r * 1.1);
}

}  // namespace hgs
