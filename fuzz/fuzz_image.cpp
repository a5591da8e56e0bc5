// Image decoding (PNG 1-16 bit incl. palette and interlaced, JPEG): `hgs train|eval|render SCENE` ->
// Scene::load_image -> load_image (3 channels; 1 for 3D-OVS masks), masks -> load_label_png, and image_size.
#include "core/error.h"
#include "core/image.h"
#include "fuzz.h"

HGS_FUZZ_TARGET(image) {
  static const auto dir = hgs::fuzz::scratch("image");
  const auto file = dir / "image.png";
  hgs::fuzz::put_file(file, {reinterpret_cast<const char*>(data), size});
  for (int channels : {3, 1}) {
    try {
      const hgs::Image img = hgs::load_image(file, channels);
      if (img.px.size() != size_t(img.width) * img.height * channels) __builtin_trap();
    } catch (const hgs::Error&) {
    }
  }
  try {
    const hgs::LabelMap m = hgs::load_label_png(file);
    if (m.v.size() != size_t(m.width) * m.height) __builtin_trap();
  } catch (const hgs::Error&) {
  }
  try {
    int w = 0, h = 0;
    hgs::image_size(file, w, h);
  } catch (const hgs::Error&) {
  }
  return 0;
}
