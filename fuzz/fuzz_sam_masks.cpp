// SAM / SAM2 mask files: `hgs masks import SCENE --from sam-json|sam2-png DIR` -> read_sam_json (COCO RLE as a
// string or a list of counts, bbox, scores) then flatten_masks and part_of as the import runs them, and
// read_sam2_png (palette index or grey value). Input: the JSON, kSplit, the PNG; both checked against a 32 x 24
// view (the tiny scene's image size).
#include "core/error.h"
#include "fuzz.h"
#include "masks/flatten.h"
#include "masks/sources.h"

HGS_FUZZ_TARGET(sam_masks) {
  static const auto dir = hgs::fuzz::scratch("sam_masks");
  const auto parts = hgs::fuzz::split(data, size, 2);
  const auto json_file = dir / "frame_00001.json", png_file = dir / "frame_00001.png";
  hgs::fuzz::put_file(json_file, parts[0]);
  hgs::fuzz::put_file(png_file, parts[1]);
  constexpr int W = 32, H = 24;
  try {
    const auto masks = hgs::masks::read_sam_json(json_file, W, H);
    const auto f = hgs::masks::flatten_masks(masks, W, H);
    if (f.labels.width != W || f.labels.height != H || f.visible.size() != masks.size()) __builtin_trap();
    const auto parent = hgs::masks::part_of(masks, 0.5);
    for (size_t i = 0; i < parent.size(); ++i)
      if (parent[i] >= int(masks.size())) __builtin_trap();
  } catch (const hgs::Error&) {
  }
  try {
    const hgs::LabelMap m = hgs::masks::read_sam2_png(png_file, W, H);
    if (m.width != W || m.height != H) __builtin_trap();
  } catch (const hgs::Error&) {
  }
  return 0;
}
