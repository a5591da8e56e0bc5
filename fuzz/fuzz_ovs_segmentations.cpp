// 3D-OVS segmentations: `hgs eval SCENE --protocol 3dovs` -> open_3dovs_labels (segmentations/classes.txt) and
// load_3dovs_view (segmentations/0/<class>.png). Input: classes.txt, kSplit, the PNG written for every class.
#include <system_error>

#include "core/error.h"
#include "eval/labels.h"
#include "fuzz.h"

HGS_FUZZ_TARGET(ovs_segmentations) {
  namespace fs = std::filesystem;
  const fs::path scene = hgs::fuzz::scratch("ovs_segmentations");
  const auto parts = hgs::fuzz::split(data, size, 2);
  const fs::path seg = scene / "segmentations";
  hgs::fuzz::put_file(seg / "classes.txt", parts[0]);
  fs::create_directories(seg / "0");
  try {
    const hgs::eval::OvsLabelSet labels = hgs::eval::open_3dovs_labels(scene);
    int written = 0;
    for (const std::string& c : labels.classes) {  // at most 8 masks; names that cannot be files are left out
      std::error_code ec;
      if (written >= 8 || c.size() > 200 || c.find('\0') != std::string::npos) continue;
      if (!fs::exists(seg / "0" / (c + ".png"), ec)) hgs::fuzz::put_file(seg / "0" / (c + ".png"), parts[1]);
      ++written;
    }
    for (int downscale : {1, 2}) {
      try {
        hgs::eval::load_3dovs_view(labels, 0, 0, 0, downscale);
      } catch (const hgs::Error&) {
      }
    }
  } catch (const hgs::Error&) {
  }
  return 0;
}
