// The first stage of `hgs prepare`: a folder of photos or a video becomes one folder of upright images of a
// bounded size, the input COLMAP reads (SCENE/prepare/input/).
//   - Photos: every regular file of the folder (not recursive), sorted by name. A file is an image by its content
//     (JPEG / PNG signature), not its extension; other files are skipped and listed. A JPEG's EXIF orientation
//     (libexif) is applied; images larger than `max_size` on their longest side are area-downscaled. An image
//     that needs neither is copied byte for byte; others are written as JPEG (quality 95) or PNG (PNG input).
//   - Video: frames through ffmpeg at `fps`; a frame whose sharpness (variance of the Laplacian of its grey
//     image) is below `blur_keep` x the median of its neighbours' is dropped as blurred.
//   - Unreadable or truncated files (decoder error, JPEG without its end marker, PNG without IEND) fail with a
//     one-line error naming the file, unless `skip_bad`, when they are skipped and listed.
// Resumable: an output that exists and whose record in out_dir/inputs.json matches its source (size, mtime,
// options) is kept; every output is written atomically.
#pragma once
#include <filesystem>
#include <string>
#include <vector>

namespace hgs {
class Progress;
}

namespace hgs::prepare {

struct InputOptions {
  int max_size = 1600;  // longest side in pixels after downscaling (0 = keep the size)
  bool skip_bad = false;
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
  std::vector<InputImage> images;       // sorted by name
  std::vector<std::string> not_images;  // files skipped as not images
  std::vector<std::string> bad;         // "<file>: <reason>" skipped with skip_bad
  std::vector<std::string> blurred;     // video frames dropped as blurred
  int reused = 0;                       // outputs kept from an earlier run
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
