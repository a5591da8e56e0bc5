// EXIF of JPEG photos through libexif: the orientation tag (which of the 8 rotations / flips displays the
// image upright), and the EXIF block to carry into a rewritten JPEG (camera and focal length, which COLMAP
// reads for its first intrinsics) with the orientation reset to 1 and the new pixel size.
#pragma once
#include <cstddef>
#include <cstdint>
#include <vector>

namespace hgs::prepare {

// The EXIF orientation (1..8) of a JPEG file's bytes; 1 when there is no EXIF or no valid orientation tag.
int exif_orientation(const uint8_t* data, size_t n);

// The JPEG's EXIF as an APP1 payload ("Exif\0\0" + TIFF) for an upright image of width x height: orientation 1,
// pixel dimensions updated, thumbnail and maker note dropped. Empty when the file has no EXIF or it does not
// fit one APP1 segment.
std::vector<uint8_t> upright_exif(const uint8_t* data, size_t n, int width, int height);

}  // namespace hgs::prepare
