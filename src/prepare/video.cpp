// A video -> out_dir/frame_NNNNN.jpg (photos.h): ffmpeg extracts frames at `fps` (scaled so the longest side is
// at most max_size; ffmpeg turns them upright by the stream's display matrix, EXIF plays no part) as quality-2
// JPEGs into a temporary folder inside out_dir, logging to out_dir/../logs/ffmpeg.log; each frame's sharpness
// (sharpness.h) decides whether it is kept; kept frames are renamed in order. inputs.json records the video's
// stamp, the options and the frames, so a rerun with the same video and options keeps them.
#include <stb/stb_image.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>

#include "core/error.h"
#include "core/fs.h"
#include "core/parallel.h"
#include "core/progress.h"
#include "prepare/input_dir.h"
#include "prepare/photos.h"
#include "prepare/pixels.h"
#include "prepare/run_tool.h"
#include "prepare/sharpness.h"

namespace hgs::prepare {
namespace fs = std::filesystem;
using nlohmann::json;

bool is_video_input(const fs::path& path) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) return false;
  const ImageKind kind = sniff_image(path);  // (unreadable: ffmpeg will say why)
  return kind == ImageKind::none || kind == ImageKind::unreadable;
}

namespace {

std::string frame_filter(const InputOptions& opt) {
  std::string f = fmt::format("fps={}", opt.fps);
  if (opt.max_size > 0)  // longest side <= max_size, never enlarged; -1 keeps the aspect ratio
    f += fmt::format(",scale=w='if(gte(iw,ih),min(iw,{0}),-1)':h='if(gte(iw,ih),-1,min(ih,{0}))'", opt.max_size);
  return f;
}

// Seconds from ffmpeg's "  Duration: HH:MM:SS.xx," line, if this is it.
std::optional<double> parse_duration(const std::string& line) {
  const size_t p = line.find("Duration: ");
  int h, m;
  double s;
  if (p == std::string::npos || std::sscanf(line.c_str() + p + 10, "%d:%d:%lf", &h, &m, &s) != 3) return {};
  return h * 3600.0 + m * 60.0 + s;
}

// Runs ffmpeg into `tmp` with a progress bar fed by its "Duration:" and "frame=" lines.
void extract_frames(const fs::path& exe, const fs::path& video, const fs::path& tmp, const fs::path& log,
                    const InputOptions& opt) {
  std::optional<Progress> bar;
  auto on_line = [&](const std::string& line) {
    if (auto d = parse_duration(line); d && !bar)
      bar.emplace("video frames", std::max(1L, long(std::ceil(*d * opt.fps))), opt.progress);
    long frame = 0;
    if (bar && line.rfind("frame=", 0) == 0 && std::sscanf(line.c_str() + 6, "%ld", &frame) == 1) bar->update(frame);
  };
  run_tool_or_fail(fmt::format("ffmpeg (frames of {})", video.string()), exe,
                   {"-nostdin", "-hide_banner", "-y", "-i", video.string(), "-vf", frame_filter(opt), "-q:v", "2",
                    (tmp / "%06d.jpg").string()},
                   log, on_line);
  if (bar) bar->finish();
}

std::vector<fs::path> list_frames(const fs::path& tmp) {
  std::vector<fs::path> frames;
  for (const auto& e : fs::directory_iterator(tmp))
    if (e.path().extension() == ".jpg") frames.push_back(e.path());
  std::sort(frames.begin(), frames.end());
  return frames;
}

// Sharpness of each frame (sharpness.h) and its size.
std::vector<double> frame_sharpness(const std::vector<fs::path>& frames, bool progress, std::vector<int>& wh) {
  std::vector<double> s(frames.size());
  wh.assign(frames.size() * 2, 0);  // [N, 2] width, height
  parallel_for_progress("frame sharpness", long(frames.size()), progress, [&](long i) {
    int w, h, c;
    uint8_t* g = stbi_load(frames[i].c_str(), &w, &h, &c, 1);
    if (!g) fail("{}: cannot decode the frame ffmpeg wrote ({})", frames[i].string(), stbi_failure_reason());
    s[i] = laplacian_variance(g, w, h);
    wh[i * 2] = w;
    wh[i * 2 + 1] = h;
    stbi_image_free(g);
  });
  return s;
}
}  // namespace

namespace {
json video_key(const fs::path& video, const InputOptions& opt) {
  return {{"kind", "video"}, {"source", video.string()}, {"source_stamp", stamp_json(file_stamp(video))},
          {"fps", opt.fps},  {"max_size", opt.max_size}, {"blur_keep", opt.blur_keep}};
}

// The earlier run's frames when the video, the options and every frame file are unchanged.
bool reuse_video(const json& old, const json& key, const fs::path& out_dir, InputReport& report) {
  if (!old.is_object() || !old.contains("images") || !old.contains("blurred")) return false;
  for (const auto& [k, v] : key.items())
    if (!old.contains(k) || old[k] != v) return false;
  InputReport r;
  for (const json& f : old["images"]) {
    const std::string name = f.value("name", "");
    if (name.empty() || !stamp_matches(f["output_stamp"], file_stamp(out_dir / name))) return false;
    r.images.push_back({f.value("source", ""), name, f.value("width", 0), f.value("height", 0), 1, false});
  }
  r.blurred = old["blurred"].get<std::vector<std::string>>();
  r.reused = static_cast<int>(r.images.size());
  report = r;
  return !r.images.empty();
}

// Moves the kept frames to out_dir/frame_NNNNN.jpg in order (all other files there removed first).
void place_frames(const fs::path& video, const std::vector<fs::path>& frames, const std::vector<double>& sharp,
                  const std::vector<int>& wh, const fs::path& out_dir, const InputOptions& opt, InputReport& report) {
  const std::vector<bool> keep = keep_sharp_frames(sharp, opt.blur_keep);
  remove_other_files(out_dir, {});
  for (size_t i = 0; i < frames.size(); ++i) {
    const std::string source = fmt::format("{}#{}", video.string(), frames[i].stem().string());
    if (!keep[i]) {
      report.blurred.push_back(source);
      continue;
    }
    const std::string name = fmt::format("frame_{:05d}.jpg", report.images.size() + 1);
    std::error_code ec;
    fs::rename(frames[i], out_dir / name, ec);
    if (ec) fail("{}: cannot move the frame into place ({})", (out_dir / name).string(), ec.message());
    report.images.push_back({source, name, wh[i * 2], wh[i * 2 + 1], 1, false});
  }
}

json video_record(const json& key, const InputReport& report, const fs::path& out_dir) {
  json rec = key, images = json::array();
  for (const InputImage& im : report.images)
    images.push_back({{"name", im.name},
                      {"source", im.source},
                      {"width", im.width},
                      {"height", im.height},
                      {"output_stamp", stamp_json(file_stamp(out_dir / im.name))}});
  rec["images"] = images;
  rec["blurred"] = report.blurred;
  return rec;
}
}  // namespace

InputReport import_video(const fs::path& video_in, const fs::path& out_dir_in, const InputOptions& opt) {
  const fs::path video = resolved_path(video_in);
  const fs::path out_dir = fs::absolute(out_dir_in).lexically_normal();
  std::error_code ec;
  if (!fs::is_regular_file(video, ec)) fail("{}: not a video file", video.string());
  if (!(opt.fps > 0)) fail("--fps {}: must be a positive number of frames per second", opt.fps);
  const fs::path exe = require_tool({opt.ffmpeg, "ffmpeg"}, "--ffmpeg");
  ensure_dir(out_dir);
  const json key = video_key(video, opt);
  InputReport report;
  if (reuse_video(read_inputs_record(out_dir), key, out_dir, report)) return report;
  fs::remove(out_dir / kInputsJson, ec);  // out_dir is in flux until the new record is written
  const fs::path tmp = out_dir / kFramesTmp, log = out_dir.parent_path() / "logs" / "ffmpeg.log";
  fs::remove_all(tmp, ec);
  ensure_dir(tmp);
  extract_frames(exe, video, tmp, log, opt);
  const std::vector<fs::path> frames = list_frames(tmp);
  if (frames.empty()) fail("{}: ffmpeg extracted no frames (is it a video?); log: {}", video.string(), log.string());
  std::vector<int> wh;
  const std::vector<double> sharp = frame_sharpness(frames, opt.progress, wh);
  place_frames(video, frames, sharp, wh, out_dir, opt, report);
  fs::remove_all(tmp, ec);
  write_inputs_record(out_dir, video_record(key, report, out_dir));
  return report;
}

}  // namespace hgs::prepare
