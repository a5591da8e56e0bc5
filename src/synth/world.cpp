// Analytic ray casting against spheres, boxes, cylinders and cones (closed-form roots) and tori (sphere
// tracing of the torus distance field inside its bounding box, since the quartic has no cheap stable root).
// Materials are 3-D procedural textures evaluated at the hit point in the primitive's frame.
#include "synth/world.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"

namespace hgs::synth {
namespace {

constexpr double kEps = 1e-7;

Vec3 to_local(const Primitive& p, const Vec3& v) {
  double c = std::cos(p.yaw), s = std::sin(p.yaw);
  return {c * v.x() + s * v.y(), -s * v.x() + c * v.y(), v.z()};
}
Vec3 to_world(const Primitive& p, const Vec3& v) {
  double c = std::cos(p.yaw), s = std::sin(p.yaw);
  return {c * v.x() - s * v.y(), s * v.x() + c * v.y(), v.z()};
}

// Ray vs axis-aligned box [-h, h]; returns entry/exit distances.
bool slab(const Vec3& o, const Vec3& d, const Vec3& h, double& t0, double& t1, int& axis0, int& axis1) {
  t0 = -1e30;
  t1 = 1e30;
  axis0 = axis1 = 0;
  for (int i = 0; i < 3; ++i) {
    if (std::abs(d[i]) < 1e-12) {
      if (o[i] < -h[i] || o[i] > h[i]) return false;
      continue;
    }
    double a = (-h[i] - o[i]) / d[i], b = (h[i] - o[i]) / d[i];
    if (a > b) std::swap(a, b);
    if (a > t0) {
      t0 = a;
      axis0 = i;
    }
    if (b < t1) {
      t1 = b;
      axis1 = i;
    }
    if (t0 > t1) return false;
  }
  return t1 > kEps;
}

double torus_sdf(const Vec3& p, double R, double r) {
  double q = std::sqrt(p.x() * p.x() + p.y() * p.y()) - R;
  return std::sqrt(q * q + p.z() * p.z()) - r;
}

// Nearest positive hit of one primitive in its local frame. Returns t and the local normal.
bool hit_local(const Primitive& p, const Vec3& o, const Vec3& d, double tmax, double& t, Vec3& n) {
  switch (p.kind) {
    case ShapeKind::Sphere: {
      double b = o.dot(d), c = o.squaredNorm() - p.a * p.a, disc = b * b - c;
      if (disc < 0) return false;
      double s = std::sqrt(disc), tt = -b - s;
      if (tt < kEps) tt = -b + s;
      if (tt < kEps || tt > tmax) return false;
      t = tt;
      n = (o + t * d) / p.a;
      return true;
    }
    case ShapeKind::Box: {
      double t0, t1;
      int a0, a1;
      if (!slab(o, d, {p.a, p.b, p.c}, t0, t1, a0, a1)) return false;
      double tt = t0 > kEps ? t0 : t1;
      int ax = t0 > kEps ? a0 : a1;
      if (tt > tmax) return false;
      t = tt;
      n = Vec3::Zero();
      n[ax] = (o + t * d)[ax] > 0 ? 1 : -1;
      return true;
    }
    case ShapeKind::Cylinder:
    case ShapeKind::Cone: {
      const bool cone = p.kind == ShapeKind::Cone;
      double best = tmax + 1;
      Vec3 bn(0, 0, 1);
      // Side: cylinder x^2+y^2 = a^2; cone x^2+y^2 = (k (c - z))^2 with k = a / (2c).
      double A, B, C;
      if (!cone) {
        A = d.x() * d.x() + d.y() * d.y();
        B = 2 * (o.x() * d.x() + o.y() * d.y());
        C = o.x() * o.x() + o.y() * o.y() - p.a * p.a;
      } else {
        double k = p.a / (2 * p.c), k2 = k * k, w = p.c - o.z();
        A = d.x() * d.x() + d.y() * d.y() - k2 * d.z() * d.z();
        B = 2 * (o.x() * d.x() + o.y() * d.y() + k2 * w * d.z());
        C = o.x() * o.x() + o.y() * o.y() - k2 * w * w;
      }
      if (std::abs(A) > 1e-14) {
        double disc = B * B - 4 * A * C;
        if (disc >= 0) {
          double s = std::sqrt(disc);
          for (double tt : {(-B - s) / (2 * A), (-B + s) / (2 * A)}) {
            if (tt < kEps || tt >= best) continue;
            Vec3 q = o + tt * d;
            if (q.z() < -p.c || q.z() > p.c) continue;
            best = tt;
            if (!cone) bn = Vec3(q.x(), q.y(), 0).normalized();
            else {
              double rr = std::sqrt(q.x() * q.x() + q.y() * q.y()) + 1e-12;
              double k = p.a / (2 * p.c);
              bn = Vec3(q.x() / rr, q.y() / rr, k).normalized();
            }
          }
        }
      }
      // Caps: bottom for both, top for the cylinder.
      if (std::abs(d.z()) > 1e-12) {
        for (int side = -1; side <= (cone ? -1 : 1); side += 2) {
          double tt = (side * p.c - o.z()) / d.z();
          if (tt < kEps || tt >= best) continue;
          Vec3 q = o + tt * d;
          if (q.x() * q.x() + q.y() * q.y() <= p.a * p.a) {
            best = tt;
            bn = Vec3(0, 0, side);
          }
        }
      }
      if (best > tmax) return false;
      t = best;
      n = bn;
      return true;
    }
    case ShapeKind::Torus: {
      double t0, t1;
      int a0, a1;
      Vec3 h(p.a + p.b, p.a + p.b, p.b);
      if (!slab(o, d, h * 1.001, t0, t1, a0, a1)) return false;
      double tt = std::max(t0, kEps);
      t1 = std::min(t1, tmax);
      for (int i = 0; i < 256 && tt <= t1; ++i) {
        double dist = torus_sdf(o + tt * d, p.a, p.b);
        if (dist < 1e-6) {
          Vec3 q = o + tt * d;
          double rxy = std::sqrt(q.x() * q.x() + q.y() * q.y()) + 1e-12;
          Vec3 ring(q.x() / rxy * p.a, q.y() / rxy * p.a, 0);
          t = tt;
          n = (q - ring).normalized();
          return true;
        }
        tt += dist;
      }
      return false;
    }
  }
  return false;
}

double hash3(int x, int y, int z) {
  uint64_t h = static_cast<uint64_t>(x) * 73856093ULL ^ static_cast<uint64_t>(y) * 19349663ULL ^
               static_cast<uint64_t>(z) * 83492791ULL;
  return (splitmix64(h) >> 11) * 0x1.0p-53;
}

// Trilinear value noise in [0, 1].
double value_noise(const Vec3& p) {
  int x = static_cast<int>(std::floor(p.x())), y = static_cast<int>(std::floor(p.y())),
      z = static_cast<int>(std::floor(p.z()));
  double fx = p.x() - x, fy = p.y() - y, fz = p.z() - z;
  auto sm = [](double t) { return t * t * (3 - 2 * t); };
  fx = sm(fx);
  fy = sm(fy);
  fz = sm(fz);
  double r = 0;
  for (int dz = 0; dz < 2; ++dz)
    for (int dy = 0; dy < 2; ++dy)
      for (int dx = 0; dx < 2; ++dx)
        r += hash3(x + dx, y + dy, z + dz) * (dx ? fx : 1 - fx) * (dy ? fy : 1 - fy) * (dz ? fz : 1 - fz);
  return r;
}

}  // namespace

bool World::intersect(const Vec3& o, const Vec3& d, double tmax, Hit& hit) const {
  bool any = false;
  for (size_t i = 0; i < prims.size(); ++i) {
    const Primitive& p = prims[i];
    Vec3 lo = to_local(p, o - p.center), ld = to_local(p, d);
    double t;
    Vec3 n;
    if (hit_local(p, lo, ld, std::min(tmax, hit.t), t, n)) {
      hit.t = t;
      hit.prim = static_cast<int>(i);
      hit.normal = to_world(p, n);
      hit.local = lo + t * ld;
      any = true;
    }
  }
  return any;
}

bool World::occluded(const Vec3& o, const Vec3& d, double tmax) const {
  for (const Primitive& p : prims) {
    Vec3 lo = to_local(p, o - p.center), ld = to_local(p, d);
    double t;
    Vec3 n;
    if (hit_local(p, lo, ld, tmax, t, n)) return true;
  }
  return false;
}

Vec3 World::albedo(const Hit& h) const {
  const Primitive& p = prims[h.prim];
  const Material& m = p.mat;
  const Vec3 q = h.local * m.scale;
  double f = 0;  // blend factor towards `second`
  switch (m.texture) {
    case Texture::Solid: f = 0; break;
    case Texture::Stripes: f = std::sin(q.z() * 3.14159) > 0.55 ? 1 : 0; break;
    case Texture::Checker:
      f = ((static_cast<int>(std::floor(q.x())) + static_cast<int>(std::floor(q.y())) +
            static_cast<int>(std::floor(q.z()))) &
           1)
              ? 1
              : 0;
      break;
    case Texture::Noise: f = value_noise(q) * 0.7 + value_noise(q * 2.7) * 0.3; break;
    case Texture::Wood: {
      double r = std::sqrt(q.x() * q.x() * 0.02 + q.z() * q.z() * 4.0) * 2 + value_noise(q * 0.5) * 2;
      f = 0.5 + 0.5 * std::sin(r * 6.28318);
      break;
    }
    case Texture::Dots: {
      Vec3 c(q.x() - std::round(q.x()), q.y() - std::round(q.y()), q.z() - std::round(q.z()));
      f = c.norm() < 0.3 ? 1 : 0;
      break;
    }
    case Texture::Planks: {
      int row = static_cast<int>(std::floor(q.y()));
      double off = hash3(row, 0, 7) * 4;
      f = 0.25 * value_noise(Vec3(q.x() * 0.3 + off, q.y() * 3, 0)) + ((q.y() - row) < 0.06 ? 0.75 : 0);
      break;
    }
  }
  return m.base * (1 - f) + m.second * f;
}

Vec3 World::background(const Vec3& d) const {
  double a = std::clamp(0.5 + 0.5 * d.z(), 0.0, 1.0);
  return sky_bottom * (1 - a) + sky_top * a;
}

Vec3 World::shade(const Vec3& o, const Vec3& d, const Hit& h, uint64_t pixel_seed) const {
  Vec3 pos = o + h.t * d;
  Vec3 n = h.normal;
  if (n.dot(d) > 0) n = -n;
  Vec3 base = albedo(h);
  // Soft shadow: two jittered shadow rays inside a small cone around the light direction.
  Vec3 u = light_dir.cross(Vec3(0, 0, 1));
  if (u.norm() < 1e-6) u = Vec3(1, 0, 0);
  u.normalize();
  Vec3 v = light_dir.cross(u);
  double lit = 0;
  uint64_t s = pixel_seed;
  for (int k = 0; k < 2; ++k) {
    double a = (splitmix64(s) >> 11) * 0x1.0p-53 * 6.283185307, r = 0.08 * std::sqrt((splitmix64(s) >> 11) * 0x1.0p-53);
    Vec3 l = (light_dir + r * (std::cos(a) * u + std::sin(a) * v)).normalized();
    double ndl = n.dot(l);
    if (ndl > 0 && !occluded(pos + n * 1e-5, l, 1e9)) lit += 0.5 * ndl;
  }
  double hemi = 0.75 + 0.25 * n.z();  // sky light from above
  return base.cwiseProduct(Vec3::Constant(ambient * hemi + (1 - ambient) * lit));
}

// ---- class pool and layouts -----------------------------------------------------------------------------

namespace {

struct ClassDef {
  const char* name;
  const char* synonym;
  ShapeKind shape;
  double a, b, c;  // shape parameters at tabletop scale (metres)
  Vec3 base, second;
  Texture tex;
  double tex_scale;
};

// One object class per line.
// clang-format off
const ClassDef kPool[] = {
    {"red mug", "coffee cup", ShapeKind::Cylinder, 0.045, 0, 0.05, {0.78, 0.1, 0.1}, {0.95, 0.9, 0.9}, Texture::Stripes, 30},
    {"green apple", "apple", ShapeKind::Sphere, 0.05, 0, 0, {0.35, 0.75, 0.15}, {0.6, 0.85, 0.2}, Texture::Noise, 40},
    {"blue book", "notebook", ShapeKind::Box, 0.1, 0.07, 0.02, {0.12, 0.2, 0.7}, {0.9, 0.9, 0.85}, Texture::Stripes, 60},
    {"yellow rubber duck", "bath toy", ShapeKind::Sphere, 0.045, 0, 0, {0.95, 0.85, 0.1}, {0.95, 0.55, 0.05}, Texture::Dots, 35},
    {"orange traffic cone", "safety cone", ShapeKind::Cone, 0.055, 0, 0.075, {0.95, 0.45, 0.05}, {0.97, 0.97, 0.97}, Texture::Stripes, 25},
    {"purple donut", "doughnut", ShapeKind::Torus, 0.045, 0.02, 0, {0.55, 0.2, 0.65}, {0.95, 0.75, 0.85}, Texture::Dots, 70},
    {"white teapot", "kettle", ShapeKind::Sphere, 0.065, 0, 0, {0.92, 0.92, 0.9}, {0.3, 0.45, 0.75}, Texture::Dots, 25},
    {"black camera", "camera", ShapeKind::Box, 0.06, 0.04, 0.035, {0.08, 0.08, 0.09}, {0.35, 0.35, 0.38}, Texture::Checker, 40},
    {"pink piggy bank", "piggy bank", ShapeKind::Sphere, 0.055, 0, 0, {0.95, 0.55, 0.7}, {0.85, 0.4, 0.55}, Texture::Noise, 30},
    {"brown teddy bear", "stuffed bear", ShapeKind::Sphere, 0.06, 0, 0, {0.5, 0.3, 0.15}, {0.35, 0.2, 0.1}, Texture::Noise, 80},
    {"cyan water bottle", "bottle", ShapeKind::Cylinder, 0.03, 0, 0.09, {0.2, 0.8, 0.85}, {0.9, 0.95, 0.95}, Texture::Stripes, 20},
    {"silver tin can", "soda can", ShapeKind::Cylinder, 0.033, 0, 0.06, {0.7, 0.72, 0.75}, {0.5, 0.5, 0.55}, Texture::Stripes, 50},
    {"golden ring", "ring", ShapeKind::Torus, 0.035, 0.012, 0, {0.85, 0.65, 0.15}, {0.95, 0.85, 0.4}, Texture::Noise, 90},
    {"wooden toy block", "building block", ShapeKind::Box, 0.04, 0.04, 0.04, {0.75, 0.55, 0.3}, {0.6, 0.4, 0.2}, Texture::Wood, 15},
    {"lime tennis ball", "tennis ball", ShapeKind::Sphere, 0.035, 0, 0, {0.75, 0.95, 0.2}, {0.95, 0.95, 0.9}, Texture::Stripes, 45},
    {"magenta party hat", "party hat", ShapeKind::Cone, 0.045, 0, 0.07, {0.85, 0.1, 0.6}, {0.95, 0.9, 0.2}, Texture::Dots, 40},
    {"navy backpack", "bag", ShapeKind::Box, 0.07, 0.045, 0.085, {0.1, 0.12, 0.35}, {0.2, 0.25, 0.5}, Texture::Checker, 30},
    {"teal flower pot", "plant pot", ShapeKind::Cone, 0.06, 0, 0.06, {0.1, 0.5, 0.5}, {0.3, 0.65, 0.6}, Texture::Noise, 30},
    {"red fire extinguisher", "extinguisher", ShapeKind::Cylinder, 0.035, 0, 0.1, {0.85, 0.05, 0.05}, {0.15, 0.15, 0.15}, Texture::Checker, 20},
    {"grey stone", "rock", ShapeKind::Sphere, 0.045, 0, 0, {0.5, 0.5, 0.48}, {0.35, 0.35, 0.33}, Texture::Noise, 60},
    {"yellow sponge", "sponge", ShapeKind::Box, 0.05, 0.035, 0.02, {0.95, 0.9, 0.35}, {0.7, 0.65, 0.15}, Texture::Dots, 80},
    {"orange basketball", "ball", ShapeKind::Sphere, 0.06, 0, 0, {0.9, 0.45, 0.1}, {0.15, 0.08, 0.05}, Texture::Stripes, 22},
};
// clang-format on
constexpr int kPoolSize = sizeof(kPool) / sizeof(kPool[0]);

Primitive make_box(Vec3 c, Vec3 half, Material m, const std::string& name) {
  Primitive p;
  p.kind = ShapeKind::Box;
  p.center = c;
  p.a = half.x();
  p.b = half.y();
  p.c = half.z();
  p.mat = m;
  p.concept_name = name;
  return p;
}

const char* shape_name(ShapeKind k) {
  switch (k) {
    case ShapeKind::Sphere: return "sphere";
    case ShapeKind::Box: return "box";
    case ShapeKind::Cylinder: return "cylinder";
    case ShapeKind::Cone: return "cone";
    case ShapeKind::Torus: return "torus";
  }
  return "";
}

// Footprint radius and height above the support of a class at a given scale.
void extent(const ClassDef& c, double s, double& radius, double& half_height) {
  switch (c.shape) {
    case ShapeKind::Sphere:
      radius = c.a * s;
      half_height = c.a * s;
      break;
    case ShapeKind::Box:
      radius = std::hypot(c.a, c.b) * s;
      half_height = c.c * s;
      break;
    case ShapeKind::Cylinder:
    case ShapeKind::Cone:
      radius = c.a * s;
      half_height = c.c * s;
      break;
    case ShapeKind::Torus:
      radius = (c.a + c.b) * s;
      half_height = c.b * s;
      break;
  }
}

}  // namespace

int class_pool_size() { return kPoolSize; }

World make_world(const std::string& preset, int num_objects, uint64_t seed) {
  if (preset != "tabletop" && preset != "room") fail("--preset: unknown preset '{}' (tabletop or room)", preset);
  if (num_objects < 1 || num_objects > kPoolSize - 2)
    fail("--objects: must be between 1 and {} (the class pool has {} names)", kPoolSize - 2, kPoolSize);
  World w;
  w.preset = preset;
  Rng rng(seed ^ 0x5157A11ULL);
  std::vector<int> order(kPoolSize);
  for (int i = 0; i < kPoolSize; ++i) order[i] = i;
  for (int i = kPoolSize - 1; i > 0; --i) std::swap(order[i], order[rng.integer(0, i)]);

  const bool room = preset == "room";
  const double s = room ? 2.2 : 1.0;  // object scale
  Material wood{{0.62, 0.45, 0.28}, {0.45, 0.3, 0.17}, Texture::Wood, 6};
  Material floor_mat{{0.55, 0.55, 0.52}, {0.4, 0.4, 0.38}, Texture::Checker, 2.5};
  // Supports: (centre x, y, top z, half size x, y) of surfaces objects stand on.
  struct Support {
    double x, y, z, hx, hy;
  };
  std::vector<Support> supports;
  if (!room) {
    const double tz = 0, th = 0.015, hx = 0.7, hy = 0.5, leg = 0.73;
    w.prims.push_back(make_box({0, 0, tz - th}, {hx, hy, th}, wood, "wooden table"));
    for (int sx : {-1, 1})
      for (int sy : {-1, 1})
        w.prims.push_back(make_box({sx * (hx - 0.05), sy * (hy - 0.05), tz - 2 * th - leg / 2}, {0.025, 0.025, leg / 2},
                                   wood, "wooden table"));
    w.prims.push_back(make_box({0, 0, -0.76 - 0.01}, {4, 4, 0.01}, floor_mat, "floor"));
    supports.push_back({0, 0, 0, 0.42, 0.28});
    w.look_center = Vec3(0, 0, 0.05);
    w.light_dir = Vec3(0.45, 0.3, 0.84).normalized();
  } else {
    Material planks{{0.6, 0.48, 0.33}, {0.3, 0.22, 0.14}, Texture::Planks, 4};
    Material wall{{0.85, 0.83, 0.78}, {0.75, 0.72, 0.66}, Texture::Noise, 3};
    Material wall2{{0.7, 0.78, 0.82}, {0.6, 0.68, 0.72}, Texture::Stripes, 2};
    const double R = 3.0, H = 2.6;
    w.prims.push_back(make_box({0, 0, -0.01}, {R, R, 0.01}, planks, "floor"));
    w.prims.push_back(make_box({R + 0.01, 0, H / 2}, {0.01, R, H / 2}, wall, "wall"));
    w.prims.push_back(make_box({-R - 0.01, 0, H / 2}, {0.01, R, H / 2}, wall2, "wall"));
    w.prims.push_back(make_box({0, R + 0.01, H / 2}, {R, 0.01, H / 2}, wall, "wall"));
    w.prims.push_back(make_box({0, -R - 0.01, H / 2}, {R, 0.01, H / 2}, wall2, "wall"));
    // Two low tables and a shelf-like block as background furniture.
    w.prims.push_back(make_box({0.9, 0.5, 0.22}, {0.45, 0.35, 0.22}, wood, "wooden table"));
    w.prims.push_back(make_box({-0.9, -0.6, 0.18}, {0.35, 0.5, 0.18}, wood, "wooden table"));
    w.prims.push_back(make_box({-1.6, 1.3, 0.5}, {0.3, 0.6, 0.5},
                               Material{{0.35, 0.35, 0.4}, {0.25, 0.25, 0.3}, Texture::Checker, 5}, "shelf"));
    supports.push_back({0.9, 0.5, 0.44, 0.35, 0.25});
    supports.push_back({-0.9, -0.6, 0.36, 0.25, 0.4});
    supports.push_back({0.0, 0.0, 0.0, 1.6, 1.6});
    w.look_center = Vec3(0, 0, 0.35);
    w.light_dir = Vec3(0.3, -0.4, 0.87).normalized();
    w.ambient = 0.45;
  }
  // Place objects with rejection sampling (no interpenetration, some close enough to occlude each other).
  struct Placed {
    double x, y, r;
    int support;
  };
  std::vector<Placed> placed;
  for (int k = 0; k < num_objects; ++k) {
    const ClassDef& c = kPool[order[k]];
    double r = 0, hh = 0;
    extent(c, s, r, hh);
    bool ok = false;
    double x = 0, y = 0;
    int si = 0;
    // In the room the first four objects try the two low tables; one that does not fit there (large objects
    // at some seeds) goes to the floor instead (the second pass; the seeds that fit never reach it).
    for (int attempt = 0; attempt < 4000 && !ok; ++attempt) {
      si = room ? (k < 4 && attempt < 2000 ? k % 2 : 2) : 0;
      if (!room && attempt >= 2000) break;
      const Support& sp = supports[si];
      x = sp.x + rng.uniform(-sp.hx + r, sp.hx - r);
      y = sp.y + rng.uniform(-sp.hy + r, sp.hy - r);
      ok = true;
      for (auto& p : placed) {
        double gap = std::hypot(p.x - x, p.y - y) - p.r - r;
        if (gap < 0.008 * s) {
          ok = false;
          break;
        }
      }
      if (room && si == 2) {  // keep floor objects off the furniture footprints
        if (std::abs(x - 0.9) < 0.45 + r && std::abs(y - 0.5) < 0.35 + r) ok = false;
        if (std::abs(x + 0.9) < 0.35 + r && std::abs(y + 0.6) < 0.5 + r) ok = false;
        if (std::abs(x + 1.6) < 0.3 + r && std::abs(y - 1.3) < 0.6 + r) ok = false;
      }
    }
    if (!ok)
      fail("--objects {}: could not place {} objects without overlap; use fewer objects", num_objects, num_objects);
    placed.push_back({x, y, r, si});
    Primitive p;
    p.kind = c.shape;
    p.a = c.a * s;
    p.b = c.b * s;
    p.c = c.c * s;
    p.yaw = rng.uniform(0, 6.283185307);
    p.center = Vec3(x, y, supports[si].z + hh + 1e-4);
    p.mat = Material{c.base, c.second, c.tex, c.tex_scale / s};
    p.instance = k + 1;
    p.concept_name = c.name;
    w.prims.push_back(p);
    w.objects.push_back({k + 1, c.name, shape_name(c.shape), p.center});
    w.synonyms.emplace_back(c.synonym, c.name);
  }
  for (int i = num_objects; i < kPoolSize; ++i) w.unused_names.push_back(kPool[order[i]].name);
  return w;
}

}  // namespace hgs::synth
