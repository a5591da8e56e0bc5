// hgs.Scene and hgs.View: a scene folder loaded by the library (load_scene), its views with intrinsics and poses
// as numpy, and per-view pixels loaded on demand: images (uint8 [H, W, 3]), masks (int32 [H, W]), confidences,
// dense features (float32 [H, W, D] upsampled, or the stored grid), text embeddings.
#include <cmath>

#include "common.h"
#include "core/error.h"

namespace hgs::py {
namespace {

pb::array mat(const double* d, pb::ssize_t r, pb::ssize_t c) {
  return take_vector(std::vector<double>(d, d + r * c), {r, c});
}

pb::array view_K(const View& v) {
  const double K[9] = {v.fx, 0, v.cx, 0, v.fy, v.cy, 0, 0, 1};
  return mat(K, 3, 3);
}

pb::array view_R(const View& v) {
  double R[9];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) R[i * 3 + j] = v.R(i, j);
  return mat(R, 3, 3);
}

pb::array view_pose(const View& v) {  // world -> camera [4, 4]
  double P[16] = {0};
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) P[i * 4 + j] = v.R(i, j);
    P[i * 4 + 3] = v.t(i);
  }
  P[15] = 1;
  return mat(P, 4, 4);
}

pb::array image_u8(const Scene& s, int vi) {
  Image img;
  {
    pb::gil_scoped_release nogil;
    img = s.load_image(vi);
  }
  std::vector<uint8_t> u8(img.px.size());
  for (size_t k = 0; k < u8.size(); ++k) u8[k] = uint8_t(std::lrint(std::clamp(img.px[k], 0.f, 1.f) * 255.f));
  return take_vector(std::move(u8), {img.height, img.width, 3});
}

pb::object mask_i32(const Scene& s, int vi) {
  std::optional<LabelMap> m = s.load_mask(vi);
  if (!m) return pb::none();
  std::vector<int32_t> v(m->v.begin(), m->v.end());
  return take_vector(std::move(v), {m->height, m->width});
}

pb::object confidence(const Scene& s, int vi) {
  std::optional<std::vector<float>> c = s.load_confidence(vi);
  if (!c) return pb::none();
  const View& v = s.views[vi];
  return take_vector(std::move(*c), {v.height, v.width});
}

pb::object features(const Scene& s, int vi, bool upsample) {
  int h = 0, w = 0, d = 0;
  std::optional<std::vector<float>> f;
  {
    pb::gil_scoped_release nogil;
    if (upsample) {
      f = s.load_features(vi, d);
      h = s.views[vi].height, w = s.views[vi].width;
    } else {
      f = s.load_feature_grid(vi, h, w, d);
    }
  }
  if (!f) return pb::none();
  return take_vector(std::move(*f), {h, w, d});
}

}  // namespace

void bind_scene(pb::module_& m) {
  pb::class_<View>(m, "View", "One posed view of a scene (read-only; intrinsics after downscaling)")
      .def_readonly("index", &View::index, "Position in Scene.views (sorted by name)")
      .def_readonly("name", &View::name, "Image name as in the COLMAP model, relative to images/")
      .def_readonly("stem", &View::stem, "Name without extension (masks/<stem>.png, features/<stem>.npy)")
      .def_readonly("width", &View::width)
      .def_readonly("height", &View::height)
      .def_property_readonly(
          "size", [](const View& v) { return pb::make_tuple(v.width, v.height); }, "(width, height) in pixels")
      .def_readonly("fx", &View::fx)
      .def_readonly("fy", &View::fy)
      .def_readonly("cx", &View::cx)
      .def_readonly("cy", &View::cy)
      .def_property_readonly("K", &view_K, "Intrinsics float64 [3, 3] (pixel-centre convention of COLMAP)")
      .def_property_readonly("R", &view_R, "World -> camera rotation float64 [3, 3]")
      .def_property_readonly(
          "t", [](const View& v) { return mat(v.t.data(), 3, 1).attr("reshape")(3); },
          "World -> camera translation float64 [3]")
      .def_property_readonly("pose", &view_pose, "World -> camera transform float64 [4, 4] (x_cam = R x + t)")
      .def_property_readonly(
          "camera_center",
          [](const View& v) {
            Eigen::Vector3d c = v.camera_center();
            return mat(c.data(), 3, 1).attr("reshape")(3);
          },
          "Camera centre in world space float64 [3]")
      .def_readonly("is_test", &View::is_test, "Whether the view is held out (test split)")
      .def_property_readonly("image_path", [](const View& v) { return v.image_path.string(); })
      .def("__repr__", [](const View& v) {
        return fmt::format("<hgs.View {} '{}' {}x{}{}>", v.index, v.name, v.width, v.height, v.is_test ? " test" : "");
      });

  pb::class_<Scene, std::shared_ptr<Scene>>(m, "Scene",
                                            "A capture on disk: COLMAP model + images, optional masks, dense "
                                            "language features and text embeddings (docs/formats.md)")
      .def_static(
          "load",
          [](const std::filesystem::path& path, int downscale) {
            if (downscale < 1 || downscale > 64) fail("{}: downscale must be 1..64, got {}", path.string(), downscale);
            pb::gil_scoped_release nogil;
            return std::make_shared<Scene>(load_scene(path, {downscale, false}));
          },
          pb::arg("path"), pb::arg("downscale") = 1,
          "Loads a scene folder (images/, sparse/0/, masks/, features/, text_embeddings.json); images are read "
          "per view on demand, downscaled by the integer factor `downscale`")
      .def_property_readonly("root", [](const Scene& s) { return s.root.string(); })
      .def_readonly("downscale", &Scene::downscale)
      .def_readonly("views", &Scene::views, "Every view, sorted by name")
      .def("__len__", [](const Scene& s) { return s.views.size(); })
      .def(
          "view", [](const Scene& s, pb::handle v) { return s.views[view_index(s, v)]; }, pb::arg("view"),
          "The view by index or name")
      .def(
          "index", [](const Scene& s, pb::handle v) { return view_index(s, v); }, pb::arg("view"),
          "Index of a view given by name (or index)")
      .def_property_readonly("train_indices", &Scene::train_indices)
      .def_property_readonly("test_indices", &Scene::test_indices)
      .def_property_readonly("has_masks", &Scene::has_masks)
      .def_property_readonly("has_features", &Scene::has_features)
      .def_property_readonly("split_source", [](const Scene& s) { return s.split_source; })
      .def_property_readonly("warnings", [](const Scene& s) { return s.warnings; })
      .def_property_readonly(
          "points",
          [](const Scene& s) {
            const auto* p = s.points.empty() ? nullptr : s.points[0].data();
            return take_vector(std::vector<float>(p, p + 3 * s.points.size()), {pb::ssize_t(s.points.size()), 3});
          },
          "Sparse SfM points float32 [P, 3] (a copy)")
      .def_property_readonly(
          "point_colors",
          [](const Scene& s) {
            const auto* p = s.point_colors.empty() ? nullptr : s.point_colors[0].data();
            return take_vector(std::vector<float>(p, p + 3 * s.point_colors.size()),
                               {pb::ssize_t(s.point_colors.size()), 3});
          },
          "Colours of the SfM points in [0, 1], float32 [P, 3]")
      .def_property_readonly(
          "object_names", [](const Scene& s) { return s.object_names; }, "Object id -> name (masks/objects.json)")
      .def_property_readonly(
          "text_embeddings",
          [](const Scene& s) {
            pb::dict d;
            for (const auto& [k, e] : s.text_embeddings)
              d[pb::str(k)] = take_vector(std::vector<float>(e), {pb::ssize_t(e.size())});
            return d;
          },
          "Phrase -> embedding float32 [D] (text_embeddings.json)")
      .def_property_readonly("num_objects", &Scene::num_objects, "Largest object id over all masks")
      .def(
          "image", [](const Scene& s, pb::handle v) { return image_u8(s, view_index(s, v)); }, pb::arg("view"),
          "The view's image, uint8 [H, W, 3]")
      .def(
          "mask", [](const Scene& s, pb::handle v) { return mask_i32(s, view_index(s, v)); }, pb::arg("view"),
          "The view's object ids, int32 [H, W] (0 = background), or None")
      .def(
          "confidence", [](const Scene& s, pb::handle v) { return confidence(s, view_index(s, v)); }, pb::arg("view"),
          "The view's mask confidences, float32 [H, W], or None")
      .def(
          "features",
          [](const Scene& s, pb::handle v, bool upsample) { return features(s, view_index(s, v), upsample); },
          pb::arg("view"), pb::arg("upsample") = true,
          "Dense language features: float32 [H, W, D] bilinearly upsampled to the image, or the stored grid "
          "[h, w, D] with upsample=False; None without features")
      .def("__repr__", [](const Scene& s) {
        return fmt::format("<hgs.Scene '{}' {} views ({} train), downscale {}>", s.root.string(), s.views.size(),
                           s.train_indices().size(), s.downscale);
      });
}

}  // namespace hgs::py
