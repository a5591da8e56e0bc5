// EXIF through libexif (exif.h). exif_data_new_from_data finds the APP1 segment of a JPEG itself; a file without
// EXIF gives empty content. Saving re-serialises the parsed tags (libexif writes the "Exif\0\0" header).
#include "prepare/exif.h"

#include <libexif/exif-data.h>

#include <algorithm>
#include <cstdlib>
#include <memory>

namespace hgs::prepare {

namespace {
using ExifPtr = std::unique_ptr<ExifData, decltype(&exif_data_unref)>;

ExifPtr load(const uint8_t* data, size_t n) {
  return ExifPtr(exif_data_new_from_data(data, static_cast<unsigned int>(std::min<size_t>(n, 1u << 30))),
                 exif_data_unref);
}

// Sets a SHORT or LONG tag of `ifd` when it is present.
void set_number(ExifData* ed, ExifIfd ifd, ExifTag tag, unsigned value) {
  ExifEntry* e = exif_content_get_entry(ed->ifd[ifd], tag);
  if (!e || e->components != 1) return;
  const ExifByteOrder order = exif_data_get_byte_order(ed);
  if (e->format == EXIF_FORMAT_SHORT) exif_set_short(e->data, order, static_cast<ExifShort>(value));
  if (e->format == EXIF_FORMAT_LONG) exif_set_long(e->data, order, value);
}
}  // namespace

int exif_orientation(const uint8_t* data, size_t n) {
  ExifPtr ed = load(data, n);
  if (!ed) return 1;
  ExifEntry* e = exif_content_get_entry(ed->ifd[EXIF_IFD_0], EXIF_TAG_ORIENTATION);
  if (!e || e->format != EXIF_FORMAT_SHORT || e->components < 1 || e->size < 2) return 1;
  const int o = exif_get_short(e->data, exif_data_get_byte_order(ed.get()));
  return o >= 1 && o <= 8 ? o : 1;
}

std::vector<uint8_t> upright_exif(const uint8_t* data, size_t n, int width, int height) {
  ExifPtr ed = load(data, n);
  if (!ed || !ed->ifd[EXIF_IFD_0] || ed->ifd[EXIF_IFD_0]->count == 0) return {};
  set_number(ed.get(), EXIF_IFD_0, EXIF_TAG_ORIENTATION, 1);
  set_number(ed.get(), EXIF_IFD_EXIF, EXIF_TAG_PIXEL_X_DIMENSION, static_cast<unsigned>(width));
  set_number(ed.get(), EXIF_IFD_EXIF, EXIF_TAG_PIXEL_Y_DIMENSION, static_cast<unsigned>(height));
  if (ExifEntry* mn = exif_content_get_entry(ed->ifd[EXIF_IFD_EXIF], EXIF_TAG_MAKER_NOTE))
    exif_content_remove_entry(ed->ifd[EXIF_IFD_EXIF], mn);
  // The thumbnail would keep the old orientation; libexif's default allocator is malloc / free.
  std::free(ed->data);
  ed->data = nullptr;
  ed->size = 0;
  unsigned char* buf = nullptr;
  unsigned int size = 0;
  exif_data_save_data(ed.get(), &buf, &size);
  std::vector<uint8_t> out;
  if (buf && size + 2 <= 0xFFFF) out.assign(buf, buf + size);
  std::free(buf);
  return out;
}

}  // namespace hgs::prepare
