// Models the viewer sends to the browser: the trained model (or one object / the scene without it) with the
// extra channel groups dropped and, optionally, the selected objects tinted, serialised as a 3DGS PLY.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "model/gaussian_model.h"

namespace hgs::viewer {

enum class Show { all, isolate, remove };

struct DisplayOptions {
  std::vector<int> objects;  // selected object ids (hard id obj_id)
  Show show = Show::all;     // all Gaussians, only the selected, or all but the selected
  bool tint = false;         // blend the selected Gaussians' base colour toward `tint_rgb`
  float tint_rgb[3] = {1.f, 0.45f, 0.f};
  float tint_amount = 0.6f;
  bool keep_extras = false;  // downloads keep obj/obj_id/lang; the browser copy drops them
};

// The model to display or download for these options. Fails (hgs::Error) when objects are given and the
// model has no obj_id group.
GaussianModel display_model(const GaussianModel& m, const DisplayOptions& opt);

// The model as the bytes of a binary 3DGS PLY file (model/ply.h layout).
std::string ply_bytes(const GaussianModel& m);

}  // namespace hgs::viewer
