// A folder of photos -> the upright, size-bounded images COLMAP reads (photos.h). Each image is checked
// (signature, truncation, decoding), turned upright by its EXIF orientation, area-downscaled to max_size, and
// written under its own name (bytes copied when nothing changes). Images are converted on the OpenMP threads;
// inputs.json records each output's source and output stamps, saved every few seconds and at the end, so that a
// rerun (even after a kill) keeps what is done.
#include "prepare/photos.h"

#include <algorithm>
#include <cctype>
#include <chrono>
#include <condition_variable>
#include <map>
#include <mutex>

#include "core/error.h"
#include "core/fs.h"
#include "core/parallel.h"
#include "prepare/exif.h"
#include "prepare/input_dir.h"
#include "prepare/names.h"
#include "prepare/pixels.h"

namespace hgs::prepare {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

struct Source {
  fs::path path;
  std::string name;
  ImageKind kind = ImageKind::none;
  FileStamp stamp;
};

struct Outcome {
  InputImage image;
  FileStamp output;
  std::string bad;  // reason, when the source is not a usable image
  bool done = false;
};

// The regular files of `dir` (links followed) in name order; entries that are links to nothing (dangling, or a
// loop) go to `broken` whatever their position. Other entries (folders, sockets) are not photos and are left out.
std::vector<fs::path> list_files(const fs::path& dir, std::vector<std::string>& broken) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) fail("{}: not a folder of photos", dir.string());
  std::vector<fs::path> files;
  fs::directory_iterator it(dir, ec);
  if (ec) fail("{}: cannot list the folder ({})", dir.string(), ec.message());
  for (; it != fs::directory_iterator(); it.increment(ec)) {
    if (ec) fail("{}: cannot list the folder ({})", dir.string(), ec.message());
    std::error_code e;  // per entry: a bad entry must not fail the listing
    const fs::file_status st = it->status(e);
    if (st.type() == fs::file_type::regular) files.push_back(it->path());
    else if (it->is_symlink(e) && (st.type() == fs::file_type::not_found || st.type() == fs::file_type::none ||
                                   st.type() == fs::file_type::unknown))
      broken.push_back(it->path().string());
  }
  auto by_name = [](const fs::path& a, const fs::path& b) { return a.filename() < b.filename(); };
  std::sort(files.begin(), files.end(), by_name);
  std::sort(broken.begin(), broken.end());
  return files;
}

// Output names must stay distinct on any file system (a.JPG and a.jpg) and not take the record's name.
void check_names(const std::vector<Source>& sources) {
  std::map<std::string, const Source*> seen;
  for (const Source& s : sources) {
    std::string low = s.name;
    std::transform(low.begin(), low.end(), low.begin(), [](unsigned char c) { return std::tolower(c); });
    if (low == kInputsJson)
      fail("{}: an image may not be named {} (the input stage's record): rename it", s.path.string(), kInputsJson);
    auto [it, fresh] = seen.emplace(low, &s);
    if (!fresh)
      fail("{}: the names {} and {} {} and would collide as input images: rename one", s.path.parent_path().string(),
           it->second->path.filename().string(), s.path.filename().string(),
           it->second->name == s.name ? "are the same once characters COLMAP cannot carry are replaced"
                                      : "differ only in case");
  }
}

json record_of(const Source& s, const Outcome& o) {
  const InputImage& im = o.image;
  return {{"name", im.name},
          {"source", im.source},
          {"source_stamp", stamp_json(s.stamp)},
          {"output_stamp", stamp_json(o.output)},
          {"width", im.width},
          {"height", im.height},
          {"orientation", im.orientation},
          {"resized", im.resized}};
}

// The earlier run's outcome for `s` when its record matches the source and its output is unchanged.
bool reuse(const json& old, const Source& s, const fs::path& out_dir, Outcome& o) {
  if (!old.is_object() || !old.contains("images")) return false;
  for (const json& r : old["images"]) {
    if (r.value("name", "") != s.name) continue;
    const FileStamp out = file_stamp(out_dir / s.name);
    if (r.value("source", "") != s.path.string() || !stamp_matches(r["source_stamp"], s.stamp) ||
        !stamp_matches(r["output_stamp"], out))
      return false;
    o.image = {s.path.string(),          s.name, r.value("width", 0), r.value("height", 0), r.value("orientation", 1),
               r.value("resized", false)};
    o.output = out;
    o.done = true;
    return true;
  }
  return false;
}

// Bounds the pixels decoded at once across the threads to `limit` (one image alone may take all of it), so the
// input stage's memory does not grow with the thread count.
class PixelBudget {
 public:
  explicit PixelBudget(int64_t limit) : limit_(limit) {}
  void acquire(int64_t n) {
    std::unique_lock<std::mutex> lock(mu_);
    cv_.wait(lock, [&] { return used_ == 0 || used_ + n <= limit_; });
    used_ += n;
  }
  void release(int64_t n) {
    {
      std::lock_guard<std::mutex> lock(mu_);
      used_ -= n;
    }
    cv_.notify_all();
  }

 private:
  std::mutex mu_;
  std::condition_variable cv_;
  int64_t limit_, used_ = 0;
};

// Checks, decodes, orients, resizes and writes one image; a bad file sets o.bad instead of throwing.
void convert(const Source& s, const fs::path& out_dir, const InputOptions& opt, PixelBudget& budget, Outcome& o) {
  std::vector<uint8_t> bytes;
  try {
    bytes = read_file_bytes(s.path);
  } catch (const Error& e) {  // "<file>: <why>" -> why
    const std::string m = e.what(), prefix = s.path.string() + ": ";
    o.bad = m.rfind(prefix, 0) == 0 ? m.substr(prefix.size()) : m;
    return;
  }
  Pixels px;
  o.bad = incomplete_reason(bytes, s.kind);
  int hw = 0, hh = 0;
  if (o.bad.empty()) o.bad = image_header_size(bytes, hw, hh);
  if (!o.bad.empty()) return;
  const int64_t need = std::min<int64_t>(int64_t(hw) * hh, opt.max_pixels);  // over the limit: refused unread
  budget.acquire(need);
  struct Release {
    PixelBudget& b;
    int64_t n;
    ~Release() { b.release(n); }
  } release{budget, need};
  o.bad = decode_rgb(bytes, px, opt.max_pixels);
  if (!o.bad.empty()) return;
  const int orientation = s.kind == ImageKind::jpeg ? exif_orientation(bytes.data(), bytes.size()) : 1;
  int w, h;
  const bool resized = fit_size(px.width, px.height, opt.max_size, w, h);
  const fs::path out = out_dir / s.name;
  if (!resized && orientation == 1) {
    atomic_write_bytes(out, bytes.data(), bytes.size());
  } else {
    if (resized) px = resize_area(px, w, h);
    px = apply_orientation(px, orientation);
    const auto enc = s.kind == ImageKind::png
                         ? encode_png_rgb(px)
                         : encode_jpeg(px, 95, upright_exif(bytes.data(), bytes.size(), px.width, px.height));
    atomic_write_bytes(out, enc.data(), enc.size());
  }
  o.image = {s.path.string(), s.name, orientation >= 5 ? h : w, orientation >= 5 ? w : h, orientation, resized};
  o.output = file_stamp(out);
  o.done = true;
}

json record(const std::vector<Source>& sources, const std::vector<Outcome>& outcomes, const InputReport& report,
            const InputOptions& opt) {
  json images = json::array();
  for (size_t i = 0; i < sources.size(); ++i)
    if (outcomes[i].done && outcomes[i].bad.empty()) images.push_back(record_of(sources[i], outcomes[i]));
  return {{"kind", "photos"}, {"max_size", opt.max_size}, {"images", images}, {"not_images", report.not_images}};
}

}  // namespace

namespace {
bool is_empty_file(const fs::path& p) {
  std::error_code ec;
  return fs::file_size(p, ec) == 0 && !ec;
}

// Sources (images by signature, and files that cannot be read: bad files) and the files that are not images, in
// name order.
std::vector<Source> find_sources(const fs::path& dir, InputReport& report) {
  std::vector<Source> sources;
  for (const fs::path& p : list_files(dir, report.broken_links)) {
    ImageKind kind = sniff_image(p);
    if (kind == ImageKind::none && has_image_extension(p) && is_empty_file(p)) kind = ImageKind::empty;
    if (kind == ImageKind::none) {
      report.not_images.push_back(p.string());
      continue;
    }
    const std::string name = colmap_safe_name(p.filename().string());
    if (name != p.filename().string()) report.renamed.push_back({p.string(), name});
    sources.push_back({p, name, kind, file_stamp(p)});
  }
  check_names(sources);
  return sources;
}

void check_out_dir(const fs::path& dir, const fs::path& out_dir) {
  std::error_code ec;
  if (fs::exists(out_dir, ec) && fs::equivalent(dir, out_dir, ec))
    fail("{}: the output folder of the input images may not be the photo folder itself", out_dir.string());
}

// The report's lists from the outcomes; throws the first bad file (in name order) unless skip_bad.
void finish_report(const std::vector<Source>& sources, const std::vector<Outcome>& outcomes, const InputOptions& opt,
                   InputReport& report) {
  for (size_t i = 0; i < sources.size(); ++i) {
    if (outcomes[i].bad.empty()) {
      report.images.push_back(outcomes[i].image);
      continue;
    }
    if (!opt.skip_bad)
      fail("{}: {}: copy it again or remove it from the folder (or --skip-bad-images)", sources[i].path.string(),
           outcomes[i].bad);
    report.bad.push_back(sources[i].path.string() + ": " + outcomes[i].bad);
  }
}
}  // namespace

InputReport import_photos(const fs::path& dir_in, const fs::path& out_dir, const InputOptions& opt) {
  // The resolved folder (links, "..", a trailing slash): the sources' paths, and so the stage key, do not depend on
  // how the folder was typed.
  const fs::path dir = resolved_path(dir_in);
  check_out_dir(dir, out_dir);
  InputReport report;
  const std::vector<Source> sources = find_sources(dir, report);
  ensure_dir(out_dir);
  json old = read_inputs_record(out_dir);
  if (!old.is_object() || old.value("kind", "") != "photos" || old.value("max_size", -1) != opt.max_size) old = nullptr;
  std::vector<Outcome> outcomes(sources.size());
  std::vector<long> todo;
  for (size_t i = 0; i < sources.size(); ++i)
    if (reuse(old, sources[i], out_dir, outcomes[i])) ++report.reused;
    else todo.push_back(long(i));
  std::mutex mu;
  PixelBudget budget(opt.max_pixels);
  auto last_save = std::chrono::steady_clock::now();
  parallel_for_progress("input images", long(todo.size()), opt.progress && !todo.empty(), [&](long k) {
    Outcome o;
    convert(sources[todo[k]], out_dir, opt, budget, o);
    std::lock_guard<std::mutex> lock(mu);
    outcomes[todo[k]] = std::move(o);
    if (std::chrono::steady_clock::now() - last_save > std::chrono::seconds(5)) {
      write_inputs_record(out_dir, record(sources, outcomes, report, opt));
      last_save = std::chrono::steady_clock::now();
    }
  });
  write_inputs_record(out_dir, record(sources, outcomes, report, opt));
  finish_report(sources, outcomes, opt, report);
  std::set<std::string> keep;
  for (const InputImage& im : report.images) keep.insert(im.name);
  remove_other_files(out_dir, keep);
  std::error_code ec;
  fs::remove_all(out_dir / kFramesTmp, ec);  // left by a killed video import into the same folder
  return report;
}

}  // namespace hgs::prepare
