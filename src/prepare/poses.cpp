// COLMAP's pose stages driven as subprocesses (see poses.h).
#include "prepare/poses.h"

#include <fmt/format.h>

#include <algorithm>
#include <fstream>
#include <map>
#include <regex>
#include <set>

#include "core/error.h"
#include "core/fs.h"
#include "core/image.h"
#include "core/progress.h"
#include "prepare/run_tool.h"
#include "scene/colmap.h"

namespace hgs::prepare {
namespace fs = std::filesystem;
namespace {

// Calls `on(i, n)` for every log line matching "<prefix>[i/n" (COLMAP's progress lines).
std::function<void(const std::string&)> counter(const std::string& prefix, std::function<void(long, long)> on) {
  auto re = std::make_shared<std::regex>(prefix + R"(\s*\[(\d+)/(\d+))");
  return [re, on](const std::string& line) {
    std::smatch m;
    if (std::regex_search(line, m, *re)) on(std::stol(m[1]), std::stol(m[2]));
  };
}

std::vector<std::string> image_names(const fs::path& dir) {
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.is_regular_file() && e.path().filename().string() != "inputs.json")
      names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  return names;
}

std::string log_path(const fs::path& work, const std::string& stage) {
  return (work / "logs" / (stage + ".log")).string();
}

}  // namespace

std::string choose_matcher(const PoseOptions& opt, int n) {
  if (opt.matcher != "auto") return opt.matcher;
  if (opt.ordered) return "sequential";
  if (n <= kExhaustiveUpTo) return "exhaustive";
  return opt.vocab_tree.empty() ? "sequential" : "vocab-tree";
}

void extract_features(const fs::path& colmap, const fs::path& input_dir, const fs::path& work, const PoseOptions& opt) {
  // One camera per image size: one run per size, each with its image list.
  std::map<std::pair<int, int>, std::vector<std::string>> by_size;
  for (const std::string& n : image_names(input_dir)) {
    int w = 0, h = 0;
    image_size(input_dir / n, w, h);
    by_size[{w, h}].push_back(n);
  }
  long total = 0, done = 0;
  for (auto& [size, names] : by_size) total += long(names.size());
  Progress bar("colmap features", total, opt.progress);
  for (auto& [size, names] : by_size) {
    const fs::path list = work / "lists" / fmt::format("images_{}x{}.txt", size.first, size.second);
    std::string text;
    for (const std::string& n : names) text += n + "\n";
    ensure_dir(list.parent_path());
    atomic_write_text(list, text);
    const long base = done;
    const std::string dims = fmt::format("{}x{}", size.first, size.second);  // clang-14 cannot capture `size`
    run_tool_or_fail("colmap feature_extractor", colmap,
                     {"feature_extractor", "--database_path", (work / "database.db").string(), "--image_path",
                      input_dir.string(), "--image_list_path", list.string(), "--ImageReader.single_camera", "1",
                      "--ImageReader.camera_model", opt.camera_model, "--SiftExtraction.use_gpu", "0",
                      "--SiftExtraction.max_num_features", std::to_string(opt.max_features)},
                     log_path(work, "features"),
                     counter("Processed file", [&](long i, long) { bar.update(base + i, dims); }));
    done += long(names.size());
  }
  bar.finish(fmt::format("{} images, {} camera{}", total, by_size.size(), by_size.size() > 1 ? "s" : ""));
}

void match_features(const fs::path& colmap, const fs::path& work, const std::string& matcher, int n_images,
                    const PoseOptions& opt) {
  std::vector<std::string> args{"--database_path", (work / "database.db").string(), "--SiftMatching.use_gpu", "0"};
  std::string prog, prefix = "Matching image";
  if (matcher == "exhaustive") {
    prog = "exhaustive_matcher";
    prefix = "Matching block";
  } else if (matcher == "sequential") {
    prog = "sequential_matcher";
    args.insert(args.end(), {"--SequentialMatching.overlap", "10", "--SequentialMatching.quadratic_overlap", "1"});
    if (!opt.vocab_tree.empty())
      args.insert(args.end(),
                  {"--SequentialMatching.loop_detection", "1", "--SequentialMatching.vocab_tree_path", opt.vocab_tree});
  } else if (matcher == "vocab-tree") {
    if (opt.vocab_tree.empty())
      fail(
          "--matcher vocab-tree needs --vocab-tree FILE (COLMAP's vocabulary trees are downloads from "
          "colmap.github.io, not part of Debian's package); or use --matcher exhaustive or sequential");
    prog = "vocab_tree_matcher";
    args.insert(args.end(), {"--VocabTreeMatching.vocab_tree_path", opt.vocab_tree});
  } else {
    fail("--matcher {}: not one of auto, exhaustive, sequential, vocab-tree", matcher);
  }
  args.insert(args.begin(), prog);
  // Exhaustive: "Matching block [i/B, j/B]" over B x B blocks of 50 images (COLMAP's block size); the others:
  // "Matching image [i/N]".
  const long B = (n_images + 49) / 50;
  Progress bar("colmap matching", matcher == "exhaustive" ? B * B : n_images, opt.progress);
  const std::regex block_re(R"(Matching block \[(\d+)/\d+, (\d+)/\d+\])");
  auto per_image = counter(prefix, [&](long i, long) { bar.update(i, matcher); });
  auto on_line = [&](const std::string& line) {
    std::smatch m;
    if (matcher != "exhaustive") per_image(line);
    else if (std::regex_search(line, m, block_re))
      bar.update((std::stol(m[1]) - 1) * B + std::stol(m[2]) - 1, "exhaustive");
  };
  run_tool_or_fail("colmap " + prog, colmap, args, log_path(work, "matching"), on_line);
  bar.finish(matcher);
}

fs::path map_poses(const fs::path& colmap, const fs::path& input_dir, const fs::path& work, int n_images,
                   const PoseOptions& opt) {
  const fs::path sparse = work / "sparse";
  fs::remove_all(sparse);
  ensure_dir(sparse);
  Progress bar("colmap mapping", n_images, opt.progress);
  std::regex reg_re(R"(Registering image #\d+ \((\d+)\))");
  // COLMAP discards models under 10 images (Mapper.min_model_size); a small capture may still be usable, and a
  // model holding too few of the images is refused by the registration check that follows.
  const fs::path log = log_path(work, "mapping");
  ToolRun r = run_tool(colmap,
                       {"mapper", "--database_path", (work / "database.db").string(), "--image_path",
                        input_dir.string(), "--output_path", sparse.string(), "--Mapper.min_model_size", "3"},
                       log, [&](const std::string& line) {
                         std::smatch m;
                         if (std::regex_search(line, m, reg_re))
                           bar.update(std::min<long>(std::stol(m[1]), n_images), "images registered");
                       });
  const bool no_model = r.last_lines.find("failed to create sparse model") != std::string::npos;
  if (!r.ok() && !no_model)
    fail("colmap mapper failed ({}): {}; log: {}", r.how_it_ended(), r.last_lines.substr(r.last_lines.rfind('\n') + 1),
         log.string());
  fs::path best;
  size_t best_n = 0;
  int models = 0;
  for (const auto& e : fs::directory_iterator(sparse)) {
    if (!e.is_directory() || !fs::exists(e.path() / "images.bin")) continue;
    ++models;
    const size_t n = read_colmap_bin(e.path()).images.size();
    if (n > best_n) best_n = n, best = e.path();
  }
  if (best.empty())
    fail(
        "colmap mapper made no model from {} images: too few matches between the images (more overlap between "
        "photos, more texture, or --matcher exhaustive); log: {}",
        n_images, log.string());
  bar.finish(
      fmt::format("{} of {} registered in the largest of {} model{}", best_n, n_images, models, models > 1 ? "s" : ""));
  return best;
}

void undistort(const fs::path& colmap, const fs::path& input_dir, const fs::path& model, const fs::path& work,
               const fs::path& scene, const PoseOptions& opt) {
  const fs::path out = work / "undistorted";
  fs::remove_all(out);
  const int n = int(read_colmap_bin(model).images.size());
  Progress bar("colmap undistort", n, opt.progress);
  run_tool_or_fail("colmap image_undistorter", colmap,
                   {"image_undistorter", "--image_path", input_dir.string(), "--input_path", model.string(),
                    "--output_path", out.string(), "--output_type", "COLMAP"},
                   log_path(work, "undistort"),
                   counter("Undistorting image", [&](long i, long) { bar.update(i, "to PINHOLE"); }));
  // COLMAP writes out/images and out/sparse/{cameras,images,points3D}.bin: move them into the scene, replacing
  // what an earlier run left only now that they are complete.
  const fs::path sparse0 = out / "sparse0";
  ensure_dir(sparse0);
  for (const char* f : {"cameras.bin", "images.bin", "points3D.bin"}) fs::rename(out / "sparse" / f, sparse0 / f);
  fs::remove_all(scene / "images");
  fs::remove_all(scene / "sparse");
  ensure_dir(scene / "sparse");
  fs::rename(out / "images", scene / "images");
  fs::rename(sparse0, scene / "sparse" / "0");
  fs::remove_all(out);
  bar.finish(fmt::format("{} images", n));
}

PoseSummary summarize_model(const fs::path& model, const std::vector<std::string>& input_names) {
  ColmapModel m = read_colmap(model);
  PoseSummary s;
  s.images = int(input_names.size());
  s.registered = int(m.images.size());
  s.cameras = int(m.cameras.size());
  s.points = int(m.points.size());
  std::set<std::string> reg;
  for (const ColmapImage& im : m.images) reg.insert(im.name);
  for (const std::string& n : input_names)
    if (!reg.count(n)) s.dropped.push_back(n);
  double err = 0, track = 0;
  for (const ColmapPoint& p : m.points) err += p.error, track += double(p.track.size());
  if (!m.points.empty()) {
    s.mean_reprojection_error = err / double(m.points.size());
    s.mean_track_length = track / double(m.points.size());
  }
  return s;
}

}  // namespace hgs::prepare
