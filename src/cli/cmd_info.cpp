// `hgs info SCENE`: what a scene folder holds and any problem with it.
#include <fmt/format.h>

#include <map>

#include "cli/command.h"
#include "core/error.h"
#include "core/npy.h"
#include "eval/instances.h"
#include "scene/scene.h"

namespace hgs::cli {
namespace {
namespace fs = std::filesystem;

// gt/instances/: how many maps, and the file the instances protocol takes their objects' names from.
void print_ground_truth(const fs::path& root) {
  const fs::path dir = root / "gt" / "instances";
  if (!fs::is_directory(dir)) return;
  size_t maps = 0;
  for (auto& e : fs::recursive_directory_iterator(dir)) maps += e.is_regular_file();
  const fs::path names = eval::object_names_file(root);
  fmt::print("ground truth gt/instances/ ({} maps), names {}\n", maps,
             fs::exists(names) ? "from " + fs::relative(names, root).generic_string()
                               : std::string("missing (no gt/objects.json or masks/objects.json)"));
}

// Views, resolutions, intrinsics and points.
void print_cameras(const Scene& s, int downscale) {
  fmt::print("scene        {}\n", fs::absolute(s.root).lexically_normal().string());
  fmt::print("views        {} ({} train, {} test; split: {})\n", s.views.size(), s.train_indices().size(),
             s.test_indices().size(), s.split_source);
  std::map<std::pair<int, int>, int> sizes;
  for (auto& v : s.views) sizes[{v.width, v.height}]++;
  std::string res;
  for (auto& [wh, n] : sizes) res += fmt::format("{}{}x{} ({} views)", res.empty() ? "" : ", ", wh.first, wh.second, n);
  fmt::print("resolution   {}{}\n", res, downscale > 1 ? fmt::format(" after --downscale {}", downscale) : "");
  std::map<std::tuple<double, double, double, double>, int> intr;
  for (auto& v : s.views) intr[{v.fx, v.fy, v.cx, v.cy}]++;
  fmt::print("cameras      {} distinct intrinsics", intr.size());
  if (intr.size() == 1) {
    auto [fx, fy, cx, cy] = intr.begin()->first;
    fmt::print(" (fx {:.1f} fy {:.1f} cx {:.1f} cy {:.1f})", fx, fy, cx, cy);
  }
  fmt::print("\n");
  fmt::print("points       {}\n", s.points.size());
}

// Image files: each header must decode and match its camera.
void check_images(const Scene& s, std::vector<std::string>& problems) {
  for (auto& v : s.views) {
    int w, h;
    try {
      image_size(v.image_path, w, h);
      if (w / (v.image_path.parent_path().filename().string().rfind("images_", 0) == 0 ? 1 : s.downscale) != v.width)
        problems.push_back(fmt::format("{}: {}x{} does not match its camera", v.image_path.string(), w, h));
    } catch (const Error& e) {
      problems.push_back(e.what());
    }
  }
}

// Masks, confidences, object names and features.
void print_masks_and_features(const Scene& s, std::vector<std::string>& problems) {
  size_t n_masks = 0, n_conf = 0, n_feat = 0;
  for (auto& v : s.views) {
    n_masks += v.mask_path.has_value();
    n_conf += v.conf_path.has_value();
    n_feat += v.feature_path.has_value();
  }
  fmt::print("masks        {} of {} views", n_masks, s.views.size());
  if (n_masks) {
    try {
      int k = s.num_objects();
      fmt::print(", {} objects", k);
    } catch (const Error& e) {
      problems.push_back(e.what());
    }
  }
  if (n_conf) fmt::print(", {} confidence maps", n_conf);
  fmt::print("\n");
  if (!s.object_names.empty()) {
    fmt::print("objects      ");
    int i = 0;
    for (auto& [id, name] : s.object_names) fmt::print("{}{}={}", i++ ? ", " : "", id, name);
    fmt::print("\n");
  }
  fmt::print("features     {} of {} views", n_feat, s.views.size());
  for (auto& v : s.views) {
    if (!v.feature_path) continue;
    try {
      NpyArray h = read_npy_header(*v.feature_path);
      if (h.shape.size() == 3)
        fmt::print(" ({}x{} grid, D = {}, {})", h.shape[1], h.shape[0], h.shape[2],
                   h.dtype == DType::F16 ? "float16" : "float32");
      else problems.push_back(fmt::format("{}: features must be [h, w, D]", v.feature_path->string()));
    } catch (const Error& e) {
      problems.push_back(e.what());
    }
    break;
  }
  fmt::print("\n");
}

// Text embeddings, LERF-OVS labels, 3D-OVS segmentations and gt/instances.
void print_labels(const Scene& s) {
  if (!s.text_embeddings.empty())
    fmt::print("text         {} phrases in text_embeddings.json (D = {})\n", s.text_embeddings.size(),
               s.text_embeddings.begin()->second.size());
  else fmt::print("text         no text_embeddings.json\n");
  size_t n_label = 0;
  if (fs::is_directory(s.label_dir()))
    for (auto& e : fs::directory_iterator(s.label_dir())) n_label += e.path().extension() == ".json";
  fmt::print("labels       {}\n",
             n_label ? fmt::format("{} LERF-OVS frames in label/", n_label) : std::string("none (label/)"));
  if (fs::exists(s.segmentation_dir() / "classes.txt")) {
    size_t n = 0;
    for (auto& e : fs::directory_iterator(s.segmentation_dir())) n += e.is_directory();
    fmt::print("segmentations {} 3D-OVS views in segmentations/\n", n);
  }
  print_ground_truth(s.root);
}

void run_info(const std::string& path, int downscale) {
  Scene s = load_scene(path, {downscale, false});
  std::vector<std::string> problems = s.warnings;
  print_cameras(s, downscale);
  check_images(s, problems);
  print_masks_and_features(s, problems);
  print_labels(s);
  if (problems.empty()) {
    fmt::print("problems     none\n");
  } else {
    fmt::print("problems     {}\n", problems.size());
    for (size_t i = 0; i < problems.size() && i < 20; ++i) fmt::print("  - {}\n", problems[i]);
    if (problems.size() > 20) fmt::print("  ... and {} more\n", problems.size() - 20);
  }
}

CommandRegistration reg(
    {"info", "Print what a scene folder holds (views, cameras, masks, features, labels) and any problem", 90,
     [](CLI::App& sub) {
       auto path = std::make_shared<std::string>();
       auto downscale = std::make_shared<int>(1);
       sub.add_option("SCENE", *path, "Scene folder (images/, sparse/0/, ...)")->required();
       sub.add_option("--downscale", *downscale, "Integer image downscale factor")->check(CLI::Range(1, 64));
       return [=] { run_info(*path, *downscale); };
     }});

}  // namespace
}  // namespace hgs::cli
