// hgs.clip.Model and hgs.sam.Model: the native OpenCLIP and SAM of src/clip, src/sam on weights the user supplies
// (.safetensors; nothing is downloaded). CLIP: text embeddings [T, D], image embeddings [D], dense MaskCLIP
// features [h, w, D]. SAM: the image embedding, prompted masks (every output token) and the automatic mask
// generator. Images are numpy [H, W, 3], uint8 or float32 in [0, 1]. Heavy calls release the GIL.
#include "clip/model.h"
#include "common.h"
#include "core/error.h"
#include "nn/gemm_bf16.h"
#include "sam/amg.h"
#include "sam/model.h"

namespace hgs::py {
namespace {

// numpy [H, W, 3] uint8 (0..255) or float32 (0..1) -> Image.
Image image_input(pb::handle obj) {
  if (!pb::isinstance<pb::array>(obj)) throw pb::type_error("image: expected a numpy array [H, W, 3]");
  pb::array a = pb::reinterpret_borrow<pb::array>(obj);
  if (a.ndim() != 3 || a.shape(2) != 3)
    throw pb::value_error(fmt::format("image: expected shape [H, W, 3], got {} dimensions", a.ndim()));
  Image img(int(a.shape(1)), int(a.shape(0)), 3);
  if (a.dtype().is(pb::dtype::of<uint8_t>())) {
    auto c = pb::array_t<uint8_t, pb::array::c_style>::ensure(a);
    for (size_t k = 0; k < img.px.size(); ++k) img.px[k] = c.data()[k] / 255.f;
  } else if (a.dtype().is(pb::dtype::of<float>())) {
    auto c = pb::array_t<float, pb::array::c_style>::ensure(a);
    std::copy_n(c.data(), img.px.size(), img.px.begin());
  } else {
    throw pb::type_error(
        fmt::format("image: expected dtype uint8 or float32, got {}", std::string(pb::str(a.dtype().attr("name")))));
  }
  return img;
}

using Clip = std::shared_ptr<clip::ClipModel>;
using Sam = std::shared_ptr<sam::SamModel>;

void bind_clip(pb::module_& m) {
  pb::class_<clip::ClipModel, Clip>(m, "Model", "Native OpenCLIP (ViT) on user-supplied weights")
      .def(pb::init([](const std::filesystem::path& path, const std::string& precision) {
             pb::gil_scoped_release nogil;
             auto c = std::make_shared<clip::ClipModel>(clip::ClipModel::load(path));
             c->set_precision(nn::parse_precision(precision, "precision"));
             return c;
           }),
           pb::arg("path"), pb::arg("precision") = "f32",
           "Loads OpenCLIP weights (.safetensors); precision f32 or bf16 (the vision tower's products)")
      .def_readonly("embed_dim", &clip::ClipModel::embed_dim, "Embedding dimension D")
      .def("describe", &clip::ClipModel::describe)
      .def(
          "embed_text",
          [](const clip::ClipModel& c, const std::vector<std::string>& texts) {
            std::vector<float> e;
            {
              pb::gil_scoped_release nogil;
              e = c.embed_text(texts);
            }
            return take_vector(std::move(e), {pb::ssize_t(texts.size()), c.embed_dim});
          },
          pb::arg("texts"), "L2-normalised text embeddings float32 [T, D]")
      .def(
          "embed_image",
          [](const clip::ClipModel& c, pb::handle image) {
            Image img = image_input(image);
            std::vector<float> e;
            {
              pb::gil_scoped_release nogil;
              e = c.embed_image(img);
            }
            return take_vector(std::move(e), {c.embed_dim});
          },
          pb::arg("image"), "L2-normalised global image embedding float32 [D]")
      .def(
          "dense_features",
          [](const clip::ClipModel& c, pb::handle image, int input_size) {
            Image img = image_input(image);
            clip::DenseOptions o;
            o.input_size = input_size;
            clip::DenseFeatures f;
            {
              pb::gil_scoped_release nogil;
              f = c.dense_features(img, o);
            }
            return take_vector(std::move(f.data), {f.h, f.w, f.dim});
          },
          pb::arg("image"), pb::arg("input_size") = 448,
          "Dense MaskCLIP features float32 [h, w, D] (unit vectors; the shorter side resized to input_size)");
}

pb::tuple predict(const sam::SamModel& s, pb::handle image, const std::vector<std::array<float, 2>>& points,
                  const std::vector<int>& labels, const std::vector<std::array<float, 4>>& boxes) {
  Image img = image_input(image);
  sam::Prompt p;
  p.points = points;
  p.labels = labels.empty() ? std::vector<int>(points.size(), 1) : labels;
  p.boxes = boxes;
  if (p.labels.size() != p.points.size())
    throw pb::value_error(fmt::format("labels: {} labels for {} points", p.labels.size(), p.points.size()));
  if (p.points.empty() && p.boxes.empty()) throw pb::value_error("predict: give at least one point or box");
  sam::Prediction r;
  std::vector<float> full;
  {
    pb::gil_scoped_release nogil;
    sam::ImageEmbedding e = s.embed(img);
    r = s.predict(e, p);
    full = s.upscale_masks(e, r.lowres.data(), r.tokens);
  }
  std::vector<uint8_t> masks(full.size());
  for (size_t k = 0; k < full.size(); ++k) masks[k] = full[k] > 0.f;
  pb::object mk = take_vector(std::move(masks), {r.tokens, img.height, img.width}).attr("view")("bool");
  return pb::make_tuple(mk, take_vector(std::move(r.iou), {r.tokens}));
}

pb::list generate(const sam::SamModel& s, pb::handle image, int points_per_side, float pred_iou_thresh,
                  float stability_score_thresh, int min_mask_region_area) {
  Image img = image_input(image);
  sam::AmgOptions o;
  o.points_per_side = points_per_side;
  o.pred_iou_thresh = pred_iou_thresh;
  o.stability_score_thresh = stability_score_thresh;
  o.min_mask_region_area = min_mask_region_area;
  std::vector<sam::AmgMask> masks;
  {
    pb::gil_scoped_release nogil;
    masks = sam::generate_masks(s, s.embed(img), o);
  }
  pb::list out;
  for (auto& mk : masks) {
    pb::dict d;
    d["segmentation"] = take_vector(std::move(mk.mask), {img.height, img.width}).attr("view")("bool");
    d["area"] = mk.area;
    d["bbox"] = pb::make_tuple(mk.bbox[0], mk.bbox[1], mk.bbox[2], mk.bbox[3]);
    d["predicted_iou"] = mk.predicted_iou;
    d["stability_score"] = mk.stability_score;
    d["point_coords"] = pb::make_tuple(mk.point[0], mk.point[1]);
    out.append(d);
  }
  return out;
}

void bind_sam(pb::module_& m) {
  pb::class_<sam::SamModel, Sam>(m, "Model", "Native SAM (ViT image encoder + mask decoder) on user-supplied weights")
      .def(pb::init([](const std::filesystem::path& path, const std::string& precision) {
             sam::SamOptions o;
             o.precision = nn::parse_precision(precision, "precision");
             pb::gil_scoped_release nogil;
             return std::make_shared<sam::SamModel>(sam::SamModel::load(path, o));
           }),
           pb::arg("path"), pb::arg("precision") = "f32",
           "Loads SAM weights (Hugging Face SamModel or segment-anything .safetensors); precision f32 or bf16")
      .def("describe", &sam::SamModel::describe)
      .def(
          "embed",
          [](const sam::SamModel& s, pb::handle image) {
            Image img = image_input(image);
            sam::ImageEmbedding e;
            {
              pb::gil_scoped_release nogil;
              e = s.embed(img);
            }
            return take_vector(std::move(e.data), {e.grid, e.grid, e.channels});
          },
          pb::arg("image"), "The image embedding float32 [grid, grid, C]")
      .def("predict", &predict, pb::arg("image"), pb::arg("points") = std::vector<std::array<float, 2>>(),
           pb::arg("labels") = std::vector<int>(), pb::arg("boxes") = std::vector<std::array<float, 4>>(),
           "Masks from prompts in image pixels: points [(x, y)], labels (1 foreground, 0 background; default all "
           "1), boxes [(x0, y0, x1, y1)]. Returns (masks bool [T, H, W], predicted IoU float32 [T]): token 0 is "
           "the single-mask output, 1..3 the multimask outputs")
      .def("generate", &generate, pb::arg("image"), pb::arg("points_per_side") = 32, pb::arg("pred_iou_thresh") = 0.88f,
           pb::arg("stability_score_thresh") = 0.95f, pb::arg("min_mask_region_area") = 0,
           "Automatic masks (segment-anything's generator): a list of dicts with segmentation bool [H, W], area, "
           "bbox (x, y, w, h), predicted_iou, stability_score, point_coords");
}

}  // namespace

void bind_nets(pb::module_& m) {
  pb::module_ c = m.def_submodule("clip", "Native OpenCLIP on user-supplied weights");
  bind_clip(c);
  pb::module_ s = m.def_submodule("sam", "Native SAM on user-supplied weights");
  bind_sam(s);
}

}  // namespace hgs::py
