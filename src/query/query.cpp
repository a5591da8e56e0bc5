#include "query/query.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include "core/error.h"
#include "core/excerpt.h"
#include "hybrid/fields.h"
#include "model/render_inputs.h"
#include "query/relevancy.h"

namespace hgs::query {

ObjectEmbeddings object_embeddings(const GaussianModel& m) {
  const auto h = hybrid::ConstHybridFields::bind(m, "query");
  const ExtraGroup *q = h.q, *f = h.f, *z = h.z;
  ObjectEmbeddings oe;
  oe.num_labels = q->dim;
  oe.dim = f->dim;
  const int L = q->dim, D = f->dim;
  std::vector<double> acc(size_t(L) * D, 0.0);
  oe.weight.assign(L, 0.f);
  oe.count.assign(L, 0);
  std::vector<float> frow(D);
  for (int i = 0; i < m.n; ++i) {
    const float op = sigmoid(m.opacity_logit[i]);
    f->row(i, frow.data());  // float32 or half storage
    const float* fi = frow.data();
    const int zi = static_cast<int>(z->data[i]);
    if (zi >= 0 && zi < L) oe.count[zi]++;
    for (int k = 0; k < L; ++k) {
      const float w = q->data[size_t(i) * L + k] * op;
      if (w < 1e-4f) continue;
      oe.weight[k] += w;
      double* a = &acc[size_t(k) * D];
      for (int d = 0; d < D; ++d) a[d] += w * fi[d];
    }
  }
  oe.e.assign(size_t(L) * D, 0.f);
  for (int k = 0; k < L; ++k) {
    double s = 0;
    for (int d = 0; d < D; ++d) s += acc[size_t(k) * D + d] * acc[size_t(k) * D + d];
    if (s <= 0) continue;
    const double inv = 1.0 / std::sqrt(s);
    for (int d = 0; d < D; ++d) oe.e[size_t(k) * D + d] = float(acc[size_t(k) * D + d] * inv);
  }
  return oe;
}

std::vector<ObjectScore> score_objects(const ObjectEmbeddings& oe, const float* text, const Canonical& canon) {
  std::vector<ObjectScore> out;
  for (int k = 1; k < oe.num_labels; ++k) {
    if (oe.weight[k] <= 0) continue;
    const float* e = &oe.e[size_t(k) * oe.dim];
    out.push_back({k, cosine(e, text, oe.dim), lerf_relevancy(e, text, canon, oe.dim)});
  }
  std::sort(out.begin(), out.end(), [](const ObjectScore& a, const ObjectScore& b) {
    return a.cosine != b.cosine ? a.cosine > b.cosine : a.object < b.object;
  });
  return out;
}

std::vector<float> render_object_opacity(render::GaussianRenderer& r, const GaussianModel& m, const render::Camera& cam,
                                         const std::vector<int>& ks) {
  const ExtraGroup* q = hybrid::ConstHybridFields::bind(m, "query").q;
  const int J = static_cast<int>(ks.size()), L = q->dim;
  std::vector<float> ch(size_t(m.n) * J);
  for (int i = 0; i < m.n; ++i)
    for (int j = 0; j < J; ++j)
      ch[size_t(i) * J + j] = (ks[j] >= 0 && ks[j] < L) ? q->data[size_t(i) * L + ks[j]] : 0.f;
  render::GaussianInputs in = render_inputs(m);
  in.extra = ch.data();
  in.num_extra = J;
  render::RenderSettings rs;
  rs.want_depth = false;
  render::RenderOutputs out;
  r.forward(cam, in, rs, out);
  return out.extra;
}

const char* relevancy_name(Relevancy v) {
  switch (v) {
    case Relevancy::Objects: return "objects";
    case Relevancy::ObjectsLerf: return "objects-lerf";
    case Relevancy::Lerf: return "lerf";
    case Relevancy::Foreground: return "foreground";
  }
  return "?";
}

const char* relevancy_description(Relevancy v) {
  switch (v) {
    case Relevancy::Objects:
      return "the text's cosine with hgs's object-embedding map sum_k A_k e_k (each object's pooled embedding "
             "rendered with its opacity; a rule of this project, not in the paper)";
    case Relevancy::ObjectsLerf:
      return "LERF's relevancy of hgs's object-embedding map sum_k A_k e_k (not in the paper)";
    case Relevancy::Lerf:
      return "LERF's relevancy of the paper's language map sum_n f_n alpha T (eq. 8 summed over objects), as "
             "LangSplat scores its field";
    case Relevancy::Foreground:
      return "LERF's relevancy of the paper's language map times the rendered foreground opacity (not in the "
             "paper)";
  }
  return "?";
}

Relevancy parse_relevancy(const std::string& name) {
  for (auto v : {Relevancy::Objects, Relevancy::ObjectsLerf, Relevancy::Lerf, Relevancy::Foreground})
    if (name == relevancy_name(v)) return v;
  fail("unknown relevancy '{}' (objects, objects-lerf, lerf or foreground)", excerpt(name));
}

std::vector<float> render_relevancy(render::GaussianRenderer& r, const GaussianModel& m, const render::Camera& cam,
                                    const float* text, const Canonical& canon, Relevancy variant,
                                    const ObjectEmbeddings* oe) {
  return std::move(render_relevancies(r, m, cam, {text}, canon, variant, oe)[0]);
}

namespace {

// Each map's pixels where hole[p] (nothing rendered) take the map's lowest value over the other pixels (0 when
// every pixel is a hole). hole: [H, W]; maps: T maps of [H, W].
void fill_holes(const std::vector<uint8_t>& hole, std::vector<std::vector<float>>& maps) {
  if (std::find(hole.begin(), hole.end(), 1) == hole.end()) return;
  for (auto& map : maps) {
    float lowest = std::numeric_limits<float>::infinity();
    for (size_t p = 0; p < map.size(); ++p)
      if (!hole[p]) lowest = std::min(lowest, map[p]);
    if (!std::isfinite(lowest)) lowest = 0.f;
    for (size_t p = 0; p < map.size(); ++p)
      if (hole[p]) map[p] = lowest;
  }
}

// Relevancy::Objects (the cosines, `lerf` false) and ObjectsLerf. F(p) = sum_k A_k(p) e_k is never formed: its
// cosine with a unit direction u is sum_k A_k(p) (e_k . u) / |F(p)|, and |F(p)|^2 = A(p)^T G A(p) with G = E E^T
// [L, L], so a pixel costs O(L^2 + L T) instead of O(L D). A pixel where F = 0 (nothing rendered: a hole in the
// model) has no cosine. With `lerf` it gets the cosines 0 (relevancy 0.5), as lerf_relevancy_map. Without, it gets
// the lowest score of the view's rendered pixels for that text: a cosine of 0 would lie far below every rendered
// pixel's where text-image cosines share an offset (CLIP's sit near 0.2), and LangSplat's min-max normalisation
// (eval/protocols.h) would then stretch one hole into a mask of nearly the whole view.
std::vector<std::vector<float>> object_map_relevancies(render::GaussianRenderer& r, const GaussianModel& m,
                                                       const render::Camera& cam,
                                                       const std::vector<const float*>& texts, const Canonical& canon,
                                                       const ObjectEmbeddings& oe, bool lerf) {
  const int L = oe.num_labels, D = oe.dim, T = static_cast<int>(texts.size()), M = static_cast<int>(canon.size());
  check_canonical(canon, D);
  std::vector<int> labels(L);
  for (int k = 0; k < L; ++k) labels[k] = k;
  const std::vector<float> A = render_object_opacity(r, m, cam, labels);  // [H, W, L]
  // Directions: the T texts, then the M canonical phrases, as unit vectors; u [L, T + M] = e_k . direction.
  std::vector<const float*> dirs(texts);
  for (const auto& c : canon) dirs.push_back(c.data());
  const int U = T + M;
  std::vector<double> u(size_t(L) * U), G(size_t(L) * L);
  for (int j = 0; j < U; ++j) {
    double n2 = 0;
    for (int d = 0; d < D; ++d) n2 += double(dirs[j][d]) * dirs[j][d];
    const double inv = n2 > 0 ? 1.0 / std::sqrt(n2) : 0.0;
    for (int k = 0; k < L; ++k) {
      double s = 0;
      for (int d = 0; d < D; ++d) s += double(oe.e[size_t(k) * D + d]) * dirs[j][d];
      u[size_t(k) * U + j] = s * inv;
    }
  }
  for (int a = 0; a < L; ++a)
    for (int b = 0; b < L; ++b) {
      double s = 0;
      for (int d = 0; d < D; ++d) s += double(oe.e[size_t(a) * D + d]) * oe.e[size_t(b) * D + d];
      G[size_t(a) * L + b] = s;
    }
  const size_t HW = size_t(cam.width) * cam.height;
  std::vector<std::vector<float>> maps(T, std::vector<float>(HW));
  std::vector<uint8_t> hole(HW, 0);  // [H, W] 1 where F = 0
#pragma omp parallel
  {
    std::vector<double> dots(U), sc(M);
#pragma omp for schedule(static)
    for (long p = 0; p < long(HW); ++p) {
      const float* a = &A[size_t(p) * L];
      double n2 = 0;
      for (int i = 0; i < L; ++i) {
        double gi = 0;
        for (int j = 0; j < L; ++j) gi += G[size_t(i) * L + j] * a[j];
        n2 += a[i] * gi;
      }
      std::fill(dots.begin(), dots.end(), 0.0);
      for (int k = 0; k < L; ++k)
        if (a[k] != 0.f)
          for (int j = 0; j < U; ++j) dots[j] += a[k] * u[size_t(k) * U + j];
      const double inv = n2 > 0 ? 1.0 / std::sqrt(n2) : 0.0;
      for (int i = 0; i < M; ++i) sc[i] = dots[T + i] * inv;
      for (int t = 0; t < T; ++t)
        maps[t][p] = lerf ? lerf_relevancy_from_cosines(dots[t] * inv, sc.data(), M) : float(dots[t] * inv);
      if (!lerf && !(n2 > 0)) hole[p] = 1;
    }
  }
  if (!lerf) fill_holes(hole, maps);
  return maps;
}

}  // namespace

std::vector<std::vector<float>> render_relevancies(render::GaussianRenderer& r, const GaussianModel& m,
                                                   const render::Camera& cam, const std::vector<const float*>& texts,
                                                   const Canonical& canon, Relevancy variant,
                                                   const ObjectEmbeddings* oe) {
  if (variant == Relevancy::Objects || variant == Relevancy::ObjectsLerf) {
    const bool lerf = variant == Relevancy::ObjectsLerf;
    if (oe) return object_map_relevancies(r, m, cam, texts, canon, *oe, lerf);
    return object_map_relevancies(r, m, cam, texts, canon, object_embeddings(m), lerf);
  }
  const auto h = hybrid::ConstHybridFields::bind(m, "query");
  const ExtraGroup *f = h.f, *q = h.q;
  const int D = f->dim;
  render::GaussianInputs in = render_inputs(m);
  // Channels [0, D): the language map sum_n f_n alpha T; channel D: the foreground opacity
  // sum_n (1 - q_{n,0}) alpha T (used by Relevancy::Foreground only).
  const int C = D + 1;
  std::vector<float> ch(size_t(m.n) * C);
#pragma omp parallel for schedule(static)
  for (int i = 0; i < m.n; ++i) {
    f->row(size_t(i), &ch[size_t(i) * C]);  // float32 channels for the renderer
    ch[size_t(i) * C + D] = 1.f - q->data[size_t(i) * q->dim];
  }
  in.extra = ch.data();
  in.num_extra = C;
  render::RenderSettings rs;
  rs.want_depth = false;
  render::RenderOutputs out;
  r.forward(cam, in, rs, out);
  const size_t HW = size_t(cam.width) * cam.height;
  std::vector<std::vector<float>> maps;
  for (const float* text : texts) {
    std::vector<float> rel = lerf_relevancy_map(out.extra.data(), HW, D, text, canon, kLerfTemperature, C);
    // Lerf: a zero feature (nothing rendered) gets 0.5, as any tie.
    if (variant == Relevancy::Foreground)
      for (size_t p = 0; p < HW; ++p)
        rel[p] = out.alpha[p] < 1e-4f ? 0.f : rel[p] * std::clamp(out.extra[p * C + D], 0.f, 1.f);
    maps.push_back(std::move(rel));
  }
  return maps;
}

std::vector<int> choose_objects(const std::vector<ObjectScore>& scores, float min_relevancy, const std::string& text,
                                float fragment_margin, const std::vector<LabelBox>* boxes,
                                const std::vector<uint8_t>* anchorable) {
  if (scores.empty()) fail("the model has no foreground objects to answer \"{}\"", excerpt(text));
  // The anchor: the best label that holds Gaussians of its own (a valid box). A label that lost its Gaussians to
  // another id keeps an embedding pooled from its soft probabilities q_{n,k}, and can rank first, but renders
  // nothing; without boxes, or when no label has one, the best label.
  // With `anchorable`, first the best label that also renders what its mask id covered (session.h:
  // QueryOptions::anchor_support).
  auto has_box = [&](int k) { return boxes && size_t(k) < boxes->size() && (*boxes)[k].valid; };
  auto may_anchor = [&](int k) { return !anchorable || (size_t(k) < anchorable->size() && (*anchorable)[k]); };
  auto first = [&](auto&& ok) {  // the best label that passes `ok`, or scores.size()
    size_t i = 0;
    while (i < scores.size() && !ok(scores[i].object)) ++i;
    return i;
  };
  size_t a = first([&](int k) { return has_box(k) && may_anchor(k); });
  if (a == scores.size()) a = first(has_box);
  if (a == scores.size()) a = 0;
  const int best = scores[a].object;
  std::vector<int> chosen = {best};
  // The fragment rule's cosine margin: a fraction of the anchor's lead over the median label, so that it means
  // the same for sharply and for weakly separated embeddings (SCL spreads them; without it they stay close).
  std::vector<float> cosines;
  for (const auto& s : scores) cosines.push_back(s.cosine);
  std::nth_element(cosines.begin(), cosines.begin() + cosines.size() / 2, cosines.end());
  const float top = scores[a].cosine;
  const float margin = fragment_margin * std::max(0.f, top - cosines[cosines.size() / 2]);
  for (size_t i = 0; i < scores.size(); ++i) {
    const int k = scores[i].object;
    if (i == a) continue;
    const bool relevant = min_relevancy > 0 && scores[i].relevancy >= min_relevancy;
    const bool fragment = fragment_margin > 0 && has_box(best) && has_box(k) && top - scores[i].cosine <= margin &&
                          boxes_meet((*boxes)[best], (*boxes)[k]);
    if (relevant || fragment) chosen.push_back(k);
  }
  return chosen;
}

std::vector<std::vector<float>> object_class_scores(render::GaussianRenderer& r, const GaussianModel& m,
                                                    const render::Camera& cam, const ObjectEmbeddings& oe,
                                                    const std::vector<const float*>& texts, const Canonical& canon) {
  const int C = static_cast<int>(texts.size());
  std::vector<int> labels;  // the labels with Gaussians: the opacity channels rendered
  for (int k = 0; k < oe.num_labels; ++k)
    if (oe.weight[k] > 0) labels.push_back(k);
  // The (channel, class, relevancy) triples that score: every class with its best foreground object (score_objects'
  // ranking), then every label no class chose (the background, a part split off its
  // whole, a second instance) with the class it is closest to.
  struct Term {
    size_t channel;
    int cls;
    float rel;
  };
  std::vector<Term> terms;
  std::vector<bool> chosen(oe.num_labels, false);
  for (int c = 0; c < C; ++c) {
    const std::vector<ObjectScore> sc = score_objects(oe, texts[c], canon);
    if (sc.empty()) continue;
    chosen[sc[0].object] = true;
    const size_t ch = std::find(labels.begin(), labels.end(), sc[0].object) - labels.begin();
    terms.push_back({ch, c, sc[0].relevancy});
  }
  for (size_t ch = 0; ch < labels.size() && C > 0; ++ch) {
    const int k = labels[ch];
    if (chosen[k]) continue;
    const float* e = &oe.e[size_t(k) * oe.dim];
    int own = 0;
    for (int c = 1; c < C; ++c)
      if (cosine(e, texts[c], oe.dim) > cosine(e, texts[own], oe.dim)) own = c;
    terms.push_back({ch, own, lerf_relevancy(e, texts[own], canon, oe.dim)});
  }
  const size_t HW = size_t(cam.width) * cam.height, L = labels.size();
  std::vector<std::vector<float>> maps(C, std::vector<float>(HW, 0.f));
  if (terms.empty()) return maps;
  const std::vector<float> A = render_object_opacity(r, m, cam, labels);  // [HW, L]
  for (size_t p = 0; p < HW; ++p)
    for (const Term& t : terms) maps[t.cls][p] += A[p * L + t.channel] * t.rel;
  return maps;
}

GaussianModel select_objects(const GaussianModel& m, const std::vector<int>& objects, bool remove) {
  const ExtraGroup* z = hybrid::ConstHybridFields::bind(m, "query").z;
  std::vector<int> keep;
  for (int i = 0; i < m.n; ++i) {
    const bool hit = std::find(objects.begin(), objects.end(), static_cast<int>(z->data[i])) != objects.end();
    if (hit != remove) keep.push_back(i);
  }
  GaussianModel out = m;
  out.gather(keep);
  return out;
}

}  // namespace hgs::query
