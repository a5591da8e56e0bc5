// Synthetic camera placement and the CPU ray tracer that renders each view: `supersample`^2 stratified
// samples per pixel for the colour (anti-aliased edges like a real photo), one centre sample for the exact
// instance id, depth and surface concept.
#include <omp.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "synth/synth.h"

namespace hgs::synth {

Intrinsics make_intrinsics(int width, int height) {
  const double fov_x = 60.0 * M_PI / 180.0;
  double f = width / (2 * std::tan(fov_x / 2));
  return {width, height, f, f, width / 2.0, height / 2.0};
}

static std::pair<Eigen::Matrix3d, Eigen::Vector3d> look_at(const Vec3& C, const Vec3& target) {
  Vec3 f = (target - C).normalized();
  Vec3 r = f.cross(Vec3(0, 0, 1));
  if (r.norm() < 1e-6) r = Vec3(1, 0, 0);
  r.normalize();
  Vec3 d = f.cross(r);
  Eigen::Matrix3d R;
  R.row(0) = r;
  R.row(1) = d;
  R.row(2) = f;
  return {R, -R * C};
}

std::vector<std::pair<Eigen::Matrix3d, Eigen::Vector3d>> make_poses(const World& w, int n, uint64_t seed) {
  Rng rng(seed ^ 0xCA3E7AULL);
  std::vector<std::pair<Eigen::Matrix3d, Eigen::Vector3d>> poses;
  for (int i = 0; i < n; ++i) {
    double az = 2 * M_PI * i / n + rng.uniform(-0.3, 0.3) * M_PI / n;
    Vec3 C, target;
    if (w.preset == "tabletop") {
      // Hemisphere orbit: elevation oscillates between ~18 and ~55 degrees over three laps of the band.
      double el = (36 + 18 * std::sin(3 * 2 * M_PI * i / n)) * M_PI / 180 + rng.uniform(-0.05, 0.05);
      double rad = 0.95 + rng.uniform(-0.08, 0.12);
      C = w.look_center + rad * Vec3(std::cos(az) * std::cos(el), std::sin(az) * std::cos(el), std::sin(el));
      target = w.look_center + Vec3(rng.uniform(-0.05, 0.05), rng.uniform(-0.05, 0.05), rng.uniform(-0.02, 0.02));
    } else {
      // Inside the room: a ring of positions at standing height, looking across the room at varying targets.
      double rad = 2.1 + rng.uniform(-0.25, 0.35);
      C = Vec3(rad * std::cos(az), rad * std::sin(az), 1.35 + rng.uniform(-0.25, 0.3));
      double ta = az + M_PI + rng.uniform(-0.45, 0.45);
      double tr = rng.uniform(0.2, 0.9);
      target = Vec3(tr * std::cos(ta), tr * std::sin(ta), rng.uniform(0.1, 0.5));
    }
    poses.push_back(look_at(C, target));
  }
  return poses;
}

RenderedView render_view(const World& w, const Intrinsics& K, const Eigen::Matrix3d& R, const Eigen::Vector3d& t,
                         int ss, const std::vector<std::string>& concept_names) {
  RenderedView v;
  v.R = R;
  v.t = t;
  v.rgb = Image(K.width, K.height, 3);
  v.instances = LabelMap(K.width, K.height);
  v.depth.assign(size_t(K.width) * K.height, 0.f);
  v.concept_id.assign(size_t(K.width) * K.height, 0);
  std::vector<uint16_t> prim_concept(w.prims.size(), 0);
  for (size_t i = 0; i < w.prims.size(); ++i) {
    auto it = std::find(concept_names.begin(), concept_names.end(), w.prims[i].concept_name);
    prim_concept[i] = static_cast<uint16_t>(it - concept_names.begin());
  }
  const Vec3 C = -R.transpose() * t;
  const Eigen::Matrix3d Rt = R.transpose();
  ss = std::max(1, ss);
#pragma omp parallel for schedule(dynamic, 4)
  for (int y = 0; y < K.height; ++y) {
    for (int x = 0; x < K.width; ++x) {
      const size_t pix = size_t(y) * K.width + x;
      // Centre sample: ground truth.
      {
        Vec3 dc((x + 0.5 - K.cx) / K.fx, (y + 0.5 - K.cy) / K.fy, 1.0);
        Vec3 d = (Rt * dc).normalized();
        Hit h;
        if (w.intersect(C, d, 1e9, h)) {
          v.instances.v[pix] = static_cast<uint16_t>(w.prims[h.prim].instance);
          v.depth[pix] = static_cast<float>((R * (C + h.t * d) + t).z());
          v.concept_id[pix] = prim_concept[h.prim];
        }
      }
      Vec3 acc(0, 0, 0);
      for (int sy = 0; sy < ss; ++sy)
        for (int sx = 0; sx < ss; ++sx) {
          Vec3 dc((x + (sx + 0.5) / ss - K.cx) / K.fx, (y + (sy + 0.5) / ss - K.cy) / K.fy, 1.0);
          Vec3 d = (Rt * dc).normalized();
          Hit h;
          uint64_t seed = pix * 131 + sy * ss + sx;
          acc += w.intersect(C, d, 1e9, h) ? w.shade(C, d, h, seed) : w.background(d);
        }
      acc /= double(ss * ss);
      for (int c = 0; c < 3; ++c) v.rgb.px[pix * 3 + c] = static_cast<float>(std::clamp(acc[c], 0.0, 1.0));
    }
  }
  return v;
}

}  // namespace hgs::synth
