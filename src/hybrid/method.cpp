#include "hybrid/method.h"

#include <chrono>
#include <cmath>
#include <random>

#include "core/error.h"
#include "core/half.h"
#include "core/parallel.h"
#include "hybrid/object_groups.h"
#include "render/binning.h"

namespace hgs::hybrid {

HybridMethod::HybridMethod(const HybridConfig& cfg, HybridData data, uint64_t seed)
    : cfg_(cfg),
      data_(std::move(data)),
      seed_(seed),
      assoc_(cfg, &data_.masks, data_.num_labels),
      object_losses_(cfg),
      semantic_(cfg, &data_) {}

void HybridMethod::attach(GaussianModel& model, train::Adam& optim, const std::vector<train::TrainView>& views) {
  const int L = data_.num_labels, D = data_.dim;
  if (data_.masks.size() != views.size() || data_.views.size() != views.size())
    fail("hybrid: {} training views but masks/features for {}", views.size(), data_.masks.size());
  ExtraGroup* q = model.find_extra(kAssociationGroup);
  if (!q) {
    q = &model.add_extra(kAssociationGroup, L, 0.f);
    for (int i = 0; i < model.n; ++i) q->data[size_t(i) * L] = 1.f;  // background until observed
  } else if (q->dim != L) {
    fail("hybrid: the model has {} object channels but the masks have {} labels", q->dim, L);
  }
  if (!model.find_extra(kHardIdGroup)) model.add_extra(kHardIdGroup, 1, 0.f);
  init_language(model);
  // f_n: a per-Gaussian parameter optimised row-sparse without a gradient buffer (semantic.h); by default stored
  // in half precision with bfloat16 moments. Its values live in the model (checkpoints save them there).
  train::AdamParam& p = optim.add(SemanticPass::kParam, D, model.n, cfg_.lr_lang, cfg_.lang_half);
  p.values = [&model] {
    ExtraGroup* g = model.find_extra(kLanguageGroup);
    return g->f16 ? train::ParamValues{nullptr, &g->half} : train::ParamValues{&g->data, nullptr};
  };
  assoc_.attach(optim);
  views_ = &views;
  HybridFields fields = HybridFields::bind(model, "hybrid");
  assoc_.refresh(model, fields, near_plane());
}

// f: random (seeded) for a new model; a model's own f is kept, converted to the configured storage.
void HybridMethod::init_language(GaussianModel& model) const {
  const int D = data_.dim;
  ExtraGroup* f = model.find_extra(kLanguageGroup);
  if (!f) {
    f = &model.add_extra(kLanguageGroup, D, 0.f, cfg_.lang_half);
    std::mt19937_64 rng(seed_ ^ 0x1A96ULL);
    std::normal_distribution<float> nd(0.f, cfg_.lang_init_std);
    if (f->f16)
      for (auto& x : f->half) x = float_to_half(nd(rng));
    else
      for (auto& x : f->data) x = nd(rng);
  } else if (f->dim != D) {
    fail("hybrid: the model's language embeddings have D = {} but the features have D = {}", f->dim, D);
  } else if (f->f16 != cfg_.lang_half) {  // e.g. a float32 PLY trained further in half precision
    std::vector<float> v = f->to_float();
    f->f16 = cfg_.lang_half;
    if (f->f16) {
      f->half.resize(v.size());
      for (size_t k = 0; k < v.size(); ++k) f->half[k] = float_to_half(v[k]);
      std::vector<float>().swap(f->data);
    } else {
      f->data = std::move(v);
      std::vector<uint16_t>().swap(f->half);
    }
  }
}

void HybridMethod::prepare(const train::ViewStep& v, const train::PrepareIO& io) {
  HybridFields fields = HybridFields::bind(v.model, "hybrid");
  const int n = v.model.n, u = v.view_index, L = data_.num_labels;
  if (cfg_.use_of && v.slot == 0) assoc_.fuse(n, fields);  // q from the logits: the same for every view of a step
  dq_.resize(size_t(n) * L);
  parallel_fill(dq_, 0.f);
  // Object channels from the renderer's SH colours of this view (0 for culled Gaussians), plus f for the no-SCL
  // ablation's full semantic render.
  objects_ = sample_objects(data_.views[u].present, cfg_.objects_per_step, v.rng);  // all unless approximating
  const std::vector<int>& anchors = semantic_.anchors_of(u);
  const int J = static_cast<int>(objects_.size());
  const int sem = (!cfg_.use_scl && cfg_.lambda_sem > 0) ? data_.dim : 0;
  layout_ = ObjectLayout{J, sem, true};  // the base render lets the object losses score far pixels once
  // The channels rendered: the object layout itself (dense), or the base channels + groups (sparse).
  const int C = cfg_.sparse_objects ? SparseLayout{sem}.total() : layout_.total();
  const int other = cfg_.sparse_objects ? SparseLayout::other() : layout_.other();
  channels_.resize(size_t(n) * C);
  const float* q = fields.q->data.data();
  if (cfg_.sparse_objects) {
    const bool fused = cfg_.use_of;  // the fusion backward reads dq: labels with s != 0 keep their own entry
    build_object_groups(n, L, J, SparseLayout{sem}, objects_.data(), q, io.projected.colors, io.projected.radii,
                        fused ? assoc_.fused_s() : nullptr, fused ? assoc_.fused_valid() : nullptr, channels_.data(),
                        groups_, fused ? assoc_.fused_base(n) : nullptr);
    io.channels.num_groups = J;
    io.channels.group_width = ObjectGroups::kWidth;
    io.channels.group_ptr = groups_.ptr.data();
    io.channels.group_id = groups_.id.data();
    io.channels.group_val = groups_.val.data();
    io.channels.group_planes = true;      // one plane per object: the object losses read its pixels contiguously
    io.channels.group_live_tiles = true;  // and only in the tiles where the object has Gaussians (the rest +0)
  } else {
    object_channels(n, L, layout_, objects_.data(), q, io.projected.colors, channels_.data());
  }
  if (sem) {
    const ExtraGroup& f = *fields.f;
#pragma omp parallel for schedule(static)
    for (int i = 0; i < n; ++i) f.row(i, &channels_[size_t(i) * C + other]);
  }
  io.channels.extra = channels_.data();
  io.channels.num_extra = C;
  // Pixel weights M_k of the SCL anchors, the hard masks of their labels in the view's label image: the
  // rasterizer returns a_{n,k} = sum_p M_k(p) alpha_n T_n.
  if (!anchors.empty()) {
    const LabelMap& lab = data_.masks[u].labels;
    if (lab.width != v.view.cam.width || lab.height != v.view.cam.height)
      fail("hybrid: view '{}' has a {}x{} mask for a {}x{} image", v.view.name, lab.width, lab.height, v.view.cam.width,
           v.view.cam.height);
    io.settings.pixel_labels = lab.v.data();
    io.settings.pixel_label_ids = anchors.data();
    io.settings.num_pixel_weights = static_cast<int>(anchors.size());
  }
}

void HybridMethod::losses(const train::ViewStep& v, const train::LossIO& io) {
  HybridFields fields = HybridFields::bind(v.model, "hybrid");
  const int W = v.view.cam.width, H = v.view.cam.height, C = layout_.total(), u = v.view_index, n = v.model.n;
  const long HW = long(W) * H;
  const auto tb0 = std::chrono::steady_clock::now();
  const int J = layout_.J;
  const SparseLayout sl{layout_.S};
  ObjectRenders renders;
  ObjectGradOut gout;
  if (cfg_.sparse_objects) {
    // The object renders: the base channels plus each object's group. The objects' colour gradients stay in the
    // losses' sparse form, which the renderer reads tile by tile (ObjectLosses::group_rows: no [H, W, 3 J]
    // buffer); their sum goes to the base colour's gradient, overwritten by the object losses. The S others (the
    // no-SCL ablation's cosine loss adds to them) need zeros; the base opacity's gradient is never read (the
    // renderer reads the first sl.grad_channels()).
    renders = ObjectRenders::sparse(io.out.extra.data(), sl.total(), sl.base_opacity(), io.out.groups.data(), J, HW)
                  .with_live_tiles(io.out.group_live.data(), render::kTileSize, W, H);
    d_dense_.resize(size_t(HW) * sl.total());
    if (layout_.S > 0) parallel_fill(d_dense_, 0.f);
    gout = {nullptr, 0, d_dense_.data() + sl.base_color(), sl.total()};
  } else {
    // The object losses overwrite the colour channels' gradient and the renderer reads only those and the S
    // others (its gradient-free opacity and base channels stay unread), so only the others, which the no-SCL
    // ablation's cosine loss adds to, need zeros.
    d_channels_.resize(size_t(HW) * C);
    if (layout_.S > 0) parallel_fill(d_channels_, 0.f);
    renders = ObjectRenders::interleaved(io.out.extra.data(), layout_);
    gout = {d_channels_.data(), C, nullptr, 3};
  }
  const auto t0 = std::chrono::steady_clock::now();
  const ObjectLossValues ov = object_losses_(v.view.image, data_.masks[u].labels, renders, objects_, gout);
  last_.app = float(ov.app);
  last_.bro = float(ov.bro);
  io.objective.add("app", cfg_.lambda_app, ov.app);
  io.objective.add("bro", cfg_.use_bro ? cfg_.lambda_bro : 0.f, ov.bro);
  const auto t1 = std::chrono::steady_clock::now();
  SemanticValues sv;
  const int Jf = static_cast<int>(semantic_.anchors_of(u).size());  // SCL anchors with pixel weights
  if (cfg_.lambda_sem > 0) {
    if (cfg_.use_scl) {
      float* da = nullptr;
      if (cfg_.sem_geometry && Jf > 0) {
        d_wsum_.resize(size_t(n) * Jf);
        da = d_wsum_.data();
      }
      sv = semantic_.contrastive(u, n, fields, Jf > 0 ? io.out.weight_sums.data() : nullptr, dq_.data(), da, v.rng,
                                 v.slot == 0);
      if (da && sv.anchors > 0) io.dout.weight_sums = da;
    } else if (cfg_.sparse_objects) {  // the others are dense channels of the sparse render
      sv = semantic_.cosine(u, W, H, io.out.extra.data(), sl.total(), sl.other(), d_dense_.data());
    } else {
      sv = semantic_.cosine(u, W, H, io.out.extra.data(), C, layout_.other(), d_channels_.data());
    }
  }
  last_.sem = float(sv.loss);
  last_.anchors = sv.anchors;
  io.objective.add("sem", cfg_.lambda_sem, sv.loss);
  const auto t2 = std::chrono::steady_clock::now();
  last_.ms_app = std::chrono::duration<double, std::milli>(t1 - t0).count();
  last_.ms_sem = std::chrono::duration<double, std::milli>(t2 - t1).count();
  last_.app_phases = object_losses_.phase_times();
  if (cfg_.sparse_objects) {  // base colour: the sum of the objects' gradients; each group: its object's
    io.dout.extra = d_dense_.data();
    io.dout.extra_grad_channels = sl.grad_channels();
    io.dout.group_rows = &ObjectLosses::group_rows;
    io.dout.group_ctx = &object_losses_;
    io.dout.group_grad_channels = ObjectGroups::kGradWidth;
  } else {
    io.dout.extra = d_channels_.data();
    io.dout.extra_grad_channels = layout_.grad_channels();  // the opacity channels only shape BRO's constant band
  }
  last_.ms_buffers =
      std::chrono::duration<double, std::milli>(t0 - tb0 + (std::chrono::steady_clock::now() - t2)).count();
}

void HybridMethod::backward(const train::ViewStep& v, const train::BackwardIO& io) {
  HybridFields fields = HybridFields::bind(v.model, "hybrid");
  const int n = v.model.n;
  // Object channels -> dq and dc, added to the RGB path's colour gradient before the renderer's
  // preprocess_backward takes it through SH.
  const int L = data_.num_labels;
  const float* q = fields.q->data.data();
  if (cfg_.sparse_objects)
    object_groups_backward(n, L, layout_.J, SparseLayout{layout_.S}, objects_.data(), q, io.projected.colors, groups_,
                           io.grads.extra.data(), io.grads.group_val.data(), dq_.data(), io.grads.colors.data(),
                           cfg_.use_of ? assoc_.fused_base(n) : nullptr);
  else
    object_channels_backward(n, L, layout_, objects_.data(), q, io.projected.colors, io.grads.extra.data(), dq_.data(),
                             io.grads.colors.data());
  assoc_.backward(n, fields, dq_.data(), v.slot == 0);
  if (!cfg_.use_scl && cfg_.lambda_sem > 0) {
    const int C = cfg_.sparse_objects ? SparseLayout{layout_.S}.total() : layout_.total();
    const int o = cfg_.sparse_objects ? SparseLayout::other() : layout_.other();
    semantic_.add_channel_grads(n, io.grads.extra.data(), C, o, v.slot == 0);
  }
}

void HybridMethod::reduce(train::Reducer& reducer) {
  assoc_.reduce(reducer);
  semantic_.reduce(reducer);
}

void HybridMethod::update(const train::UpdateIO& io) {
  assoc_.update(io.optim, io.grad_scale);
  HybridFields fields = HybridFields::bind(io.model, "hybrid");
  semantic_.update(io.model.n, fields, io.optim, io.grad_scale);
}

float HybridMethod::near_plane() const { return views_->front().cam.near_plane; }

void HybridMethod::after_step(const train::StepEnd& end) {
  HybridFields fields = HybridFields::bind(end.model, "hybrid");
  // The table is rebuilt every fusion_every images seen: in the step that covers a multiple of it.
  const int prev = end.iteration - 1, cur = end.images_seen, fe = cfg_.fusion_every;
  // Otherwise z = argmax q holds already: q changes between rebuilds only in fuse(), which writes z with it.
  if (end.densified || (fe > 0 && cur / fe > prev / fe)) assoc_.refresh(end.model, fields, near_plane());
}

void HybridMethod::release() {
  object_losses_.release();
  semantic_.release();
  assoc_.release();
  for (auto* v : {&dq_, &channels_, &d_channels_, &d_wsum_, &d_dense_}) std::vector<float>().swap(*v);
  groups_ = ObjectGroups{};
}

train::MethodStats HybridMethod::stats() const {
  train::MethodStats s;
  s.values = {{"app", last_.app},
              {"bro", last_.bro},
              {"sem", last_.sem},
              {"anchors", last_.anchors},
              {"ms_app", last_.ms_app},
              {"ms_sem", last_.ms_sem},
              {"ms_app_boxes", last_.app_phases.boxes},
              {"ms_app_pieces", last_.app_phases.pieces},
              {"ms_app_finish", last_.app_phases.finish},
              {"ms_app_scatter", last_.app_phases.scatter},
              {"tasks_app_pieces", last_.app_phases.pieces_tasks},
              {"tasks_app_finish", last_.app_phases.finish_tasks},
              {"ms_buffers", last_.ms_buffers}};
  s.arrays = {{"view_weights", assoc_.weights()}};
  return s;
}

std::vector<std::pair<std::string, std::vector<float>>> HybridMethod::state() const {
  // The observation table reflects the centres of the last refresh, so a resumed run continues bit for bit
  // (the view logits and f are registered parameters: the trainer saves them). Values are exact in float32.
  const auto& t = assoc_.table().label;
  return {{"observations", std::vector<float>(t.begin(), t.end())}};
}

void HybridMethod::state_loaded(const std::string& where, const nlohmann::json& config, int n,
                                std::map<std::string, std::vector<float>>& arrays) {
  // The checkpoint's hybrid options replace the current ones (as its TrainConfig does), except that SCL on or
  // off must agree: the no-SCL ablation needs the raw feature grids, loaded (or not) before the checkpoint.
  HybridConfig c = cfg_;
  if (!config.is_null()) {
    c = HybridConfig::from_json(config);
    if (c.use_scl != cfg_.use_scl)
      fail("{}: the checkpoint was trained {} --no-scl; resume with the same option", where,
           c.use_scl ? "without" : "with");
  }
  const size_t U = data_.masks.size();
  const auto& table = arrays["observations"];
  if (table.size() != size_t(n) * U)
    fail("{}: the hybrid state does not match {} training views and {} Gaussians", where, U, n);
  for (float v : table)  // written from 16-bit object ids: anything else is corruption (and casting it undefined)
    if (!(v >= 0 && v <= 65535 && v == std::floor(v))) fail("{}: corrupt observation table (value {})", where, v);
  // Checked: take it.
  if (c.scl_background != cfg_.scl_background) {  // the views' SCL classes follow the checkpoint's rule
    for (HybridView& hv : data_.views) hv.scl = scl_classes(hv.fg, hv.area[0], c.scl_background, c.min_mask_pixels);
    semantic_ = SemanticPass(c, &data_);
  }
  cfg_ = c;
  assoc_.set_config(c);
  semantic_.set_config(c);
  object_losses_ = ObjectLosses(c);  // its losses carry lambda_dssim
  assoc_.restore_table(n, std::vector<uint16_t>(table.begin(), table.end()));
}

}  // namespace hgs::hybrid
