// `hgs masks import`: SAM / SAM2 / LangSplat outputs -> the scene's masks/ (and features/ for LangSplat).
// Everything is written into hidden temporary folders inside SCENE and moved into place at the end, so a
// failure leaves the scene as it was.
#pragma once
#include <filesystem>
#include <string>
#include <vector>

namespace hgs::masks {

struct ImportOptions {
  std::filesystem::path scene;
  std::string from;               // sam-json | sam-png | sam2-png | langsplat
  std::filesystem::path dir;      // the tool's output folder
  std::string level = "default";  // LangSplat level: default | s | m | l
  bool level_given = false;       // --level was passed (only valid with langsplat)
  int feature_stride = 8;         // LangSplat feature grid cell, in seg-map pixels
  bool force = false;             // replace an existing masks/ (and features/)
  bool progress = true;
};

struct ImportSummary {
  int views = 0;                                // views in the COLMAP model
  int imported = 0;                             // views that got a label map
  size_t masks = 0;                             // source masks read (all views)
  size_t hidden = 0;                            // of which no pixel is left after flattening
  bool confidence = false;                      // masks/<stem>.conf.npy written
  bool features = false;                        // features/<stem>.npy written
  int feature_dim = 0, grid_w = 0, grid_h = 0;  // last feature grid
  std::vector<std::string> missing;             // view names without a source file
};

const std::vector<std::string>& import_formats();
// Level name -> index in LangSplat's [4, h, w] seg maps.
int langsplat_level(const std::string& name);

ImportSummary import_masks(const ImportOptions& opt);

}  // namespace hgs::masks
