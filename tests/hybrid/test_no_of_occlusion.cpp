// The occlusion test in the no-OF ablation (ObjectAssociation::refresh): the single-view assignment takes the
// label of the first view where a Gaussian's centre is visible, so that Table 3's no-OF rows differ from the full
// method by Observation Fusion's vote alone. A small Gaussian hidden behind a wall in the first view takes the
// wall's label without the test and its own (seen from the other side in the second view) with it.
#include <gtest/gtest.h>

#include "hybrid/association.h"
#include "hybrid/fields.h"
#include "render/renderer.h"

using namespace hgs;
using namespace hgs::hybrid;

namespace {

// A 10x10 pinhole view (f = 10, principal point at the centre) whose every pixel has label `label`;
// world -> camera x_c = R x + t.
MaskView view(uint16_t label, const double (&R)[9], const double (&t)[3]) {
  MaskView v;
  v.width = v.height = 10;
  v.fx = v.fy = 10;
  v.cx = v.cy = 5;
  std::copy(R, R + 9, v.R);
  std::copy(t, t + 3, v.t);
  v.labels = LabelMap(10, 10, label);
  return v;
}

}  // namespace

TEST(NoOfAssignment, KeepsTheOcclusionTest) {
  // Gaussian 0: an opaque wall at z = 1 (scale 1 across, thin in z) covering view 0's image; Gaussian 1: a small
  // opaque Gaussian at z = 3, behind the wall in view 0. View 0: camera at the origin looking down +z, every
  // pixel labelled 1 (the wall's mask). View 1: camera at z = 6 looking down -z (rotated 180 degrees about y),
  // every pixel labelled 2 (the small Gaussian's mask): the small Gaussian (depth 3) is in front of the wall
  // (depth 5) there.
  GaussianModel m;
  m.sh_degree = 0;
  m.resize(2);
  m.mean = {0.f, 0.f, 1.f, 0.f, 0.f, 3.f};
  m.log_scale = {0.f, 0.f, -4.f, -2.f, -2.f, -2.f};
  m.quat = {1.f, 0.f, 0.f, 0.f, 1.f, 0.f, 0.f, 0.f};
  m.opacity_logit = {6.f, 6.f};
  m.sh.assign(6, 1.f);
  const int L = 3;  // background 0, the wall's label 1, the small Gaussian's label 2
  m.add_extra(kAssociationGroup, L, 1.f / L);
  m.add_extra(kHardIdGroup, 1);
  m.add_extra(kLanguageGroup, 4);
  HybridFields h = HybridFields::bind(m, "test");
  const std::vector<MaskView> views = {view(1, {1, 0, 0, 0, 1, 0, 0, 0, 1}, {0, 0, 0}),
                                       view(2, {-1, 0, 0, 0, 1, 0, 0, 0, -1}, {0, 0, 6})};
  for (bool occlusion_test : {false, true}) {
    SCOPED_TRACE(occlusion_test);
    HybridConfig cfg;
    cfg.use_of = false;
    cfg.occlusion_test = occlusion_test;
    ObjectAssociation assoc(cfg, &views, L);
    assoc.refresh(m, h, render::kDefaultNearPlane);
    // Without the test the first view that sees the centre, view 0, names it: the wall's label 1. With the test
    // view 0 does not see it (hidden behind the wall) and view 1 names it: its own label 2.
    EXPECT_EQ(h.hard_id(1), occlusion_test ? 2 : 1);
    EXPECT_EQ(std::vector<float>(h.q_row(1), h.q_row(1) + L),
              occlusion_test ? std::vector<float>({0, 0, 1}) : std::vector<float>({0, 1, 0}));
    EXPECT_EQ(assoc.table().label[1 * 2 + 0], occlusion_test ? kNoObservation : 1);  // Gaussian 1 in view 0
    // The wall is in front in view 0 either way: label 1.
    EXPECT_EQ(h.hard_id(0), 1);
  }
}
