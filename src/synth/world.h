// The synthetic world: analytic primitives with procedural materials, a light, and the scene layouts
// (presets "tabletop" and "room"). Ray casting returns the first hit with its instance id.
#pragma once
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "synth/rng.h"

namespace hgs::synth {

using Vec3 = Eigen::Vector3d;

enum class ShapeKind { Sphere, Box, Cylinder, Cone, Torus };
enum class Texture { Solid, Stripes, Checker, Noise, Wood, Dots, Planks };

struct Material {
  Vec3 base{0.5, 0.5, 0.5}, second{0.2, 0.2, 0.2};
  Texture texture = Texture::Solid;
  double scale = 20;  // texture frequency (1/m)
};

// A primitive in its own frame: centred at `center`, rotated by `yaw` about +z.
// Sphere: a = radius. Box: a, b, c = half extents. Cylinder / Cone: a = radius, c = half height (cone apex at
// +c). Torus: a = major radius, b = minor radius, lying flat (axis +z).
struct Primitive {
  ShapeKind kind = ShapeKind::Sphere;
  Vec3 center{0, 0, 0};
  double yaw = 0;
  double a = 0, b = 0, c = 0;
  Material mat;
  int instance = 0;          // 0 = background (table, floor, walls); k = object k
  std::string concept_name;  // name of the thing it is ("red mug", "wooden table", ...)
};

struct Hit {
  double t = 1e30;
  int prim = -1;
  Vec3 normal{0, 0, 1};
  Vec3 local{0, 0, 0};  // hit point in the primitive's frame (for textures)
};

struct ObjectInfo {
  int id;
  std::string name;
  std::string shape;
  Vec3 position;
};

struct World {
  std::vector<Primitive> prims;
  std::vector<ObjectInfo> objects;                            // ids 1..K in order
  std::vector<std::string> unused_names;                      // pool entries not placed (distractor phrases)
  std::vector<std::pair<std::string, std::string>> synonyms;  // (synonym, class name)
  Vec3 light_dir{0.4, 0.3, 0.86};                             // towards the light, unit
  double ambient = 0.35;
  Vec3 sky_top{0.78, 0.82, 0.9}, sky_bottom{0.55, 0.55, 0.58};
  // Camera placement
  Vec3 look_center{0, 0, 0};
  std::string preset;

  bool intersect(const Vec3& o, const Vec3& d, double tmax, Hit& hit) const;
  bool occluded(const Vec3& o, const Vec3& d, double tmax) const;
  Vec3 albedo(const Hit& h) const;
  Vec3 shade(const Vec3& o, const Vec3& d, const Hit& h, uint64_t pixel_seed) const;
  Vec3 background(const Vec3& d) const;
};

// Builds a world. `num_objects` objects are drawn from the class pool (which holds more names than any scene
// uses); the rest of the pool becomes distractor phrases.
World make_world(const std::string& preset, int num_objects, uint64_t seed);

// Number of classes in the pool (upper bound for --objects).
int class_pool_size();

}  // namespace hgs::synth
