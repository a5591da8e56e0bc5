// The first stage of `hgs prepare`: a folder of photos or a video becomes one folder of upright images of a
// bounded size, the input COLMAP reads (SCENE/prepare/input/).
//   - Photos: every regular file of the folder (not recursive; links followed), sorted by name. A file is an image
//     by its content (JPEG / PNG signature), not its extension; other files are skipped and listed, and so are
//     links to nothing (dangling, or a loop), wherever they sort. A name COLMAP cannot carry (backslash, control
//     characters: names.h) is written under a safe name and the renaming listed. A JPEG's EXIF orientation
//     (libexif) is applied; images larger than `max_size` on their longest side are area-downscaled. An image
//     that needs neither is copied byte for byte; others are written as JPEG (quality 95) or PNG (PNG input).
//     When a JPEG is rewritten its EXIF (camera, focal length: COLMAP's first intrinsics) is carried over with the
//     orientation reset to 1, the new pixel size, and no thumbnail or maker note.
//   - Video: frames through ffmpeg at `fps`, scaled so the longest side is at most `max_size`, as quality-2 JPEGs
//     frame_00001.jpg ... (kept frames renumbered in order); ffmpeg turns frames upright by the stream's display
//     matrix (EXIF plays no part); its log is out_dir/../logs/ffmpeg.log. A frame is dropped as blurred when its
//     sharpness (variance of the 3x3 Laplacian of its grey image) is below `blur_keep` x the median sharpness of
//     the frames within +-5 of it (itself included), so runs of up to 5 blurred frames in a row are dropped while
//     a video that is soft throughout keeps its frames.
//   - Unreadable, empty or truncated files (decoder error, a zero-byte file named like an image, JPEG whose markers
//     end before EOI -- data after EOI, such as zero padding or a motion photo's video, is fine --, PNG without
//     IEND), and images of more than `max_pixels` pixels by their header (checked before anything is decoded: a
//     few KB can declare 16383 x 16383), fail with a one-line error naming the file, unless `skip_bad`, when they
//     are skipped and listed. Decoding holds at most about max_pixels decoded pixels at once across the threads
//     (a large image waits for the others), so memory stays bounded at any thread count.
// out_dir belongs to this stage: it always ends holding exactly the outputs of the input (other files there are
// removed) and out_dir/inputs.json, the record of each output (source path, size and mtime; the options; the
// output's size, mtime, width, height and orientation). Resumable: an output whose record matches its source,
// the options and the output file is kept (`reused`), others are redone; a kill at any moment leaves whole files
// only (atomic writes; the record is saved every few seconds). Images are converted on the OpenMP threads.
#pragma once
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace hgs {
class Progress;
}

namespace hgs::prepare {

inline constexpr int64_t kDefaultMaxPixels = 120'000'000;

struct InputOptions {
  int max_size = 1600;  // longest side in pixels after downscaling (0 = keep the size)
  bool skip_bad = false;
  // Most pixels an image may declare (width x height). 120 MP holds every camera in common use (108 MP phones,
  // 100 MP medium format) at ~360 MB decoded; a larger one (a 200 MP phone mode) needs a higher value.
  int64_t max_pixels = kDefaultMaxPixels;
  // video
  double fps = 2.0;
  double blur_keep = 0.5;
  std::string ffmpeg = "ffmpeg";  // program name or path
  bool progress = true;
};

struct InputImage {
  std::string source;         // the file it came from (a photo), or "<video>#<frame index>"
  std::string name;           // file name in out_dir
  int width = 0, height = 0;  // as written
  int orientation = 1;        // EXIF orientation applied (1 = none)
  bool resized = false;
};

struct InputReport {
  std::vector<InputImage> images;                            // sorted by name
  std::vector<std::string> not_images;                       // files skipped as not images
  std::vector<std::string> bad;                              // "<file>: <reason>" skipped with skip_bad
  std::vector<std::string> blurred;                          // video frames dropped as blurred
  std::vector<std::string> broken_links;                     // symbolic links to nothing (dangling, or a loop): skipped
  std::vector<std::pair<std::string, std::string>> renamed;  // source -> name in out_dir (names.h)
  int reused = 0;                                            // outputs kept from an earlier run
};

// True when `path` is a video file ffmpeg should read (a regular file that is not a JPEG / PNG image).
bool is_video_input(const std::filesystem::path& path);

// A folder of photos -> out_dir (see above). Fails when `dir` is not a folder.
InputReport import_photos(const std::filesystem::path& dir, const std::filesystem::path& out_dir,
                          const InputOptions& opt);

// A video -> out_dir/frame_NNNNN.jpg (see above). Fails when ffmpeg is missing (naming Debian's ffmpeg package)
// or cannot read the file.
InputReport import_video(const std::filesystem::path& video, const std::filesystem::path& out_dir,
                         const InputOptions& opt);

}  // namespace hgs::prepare
