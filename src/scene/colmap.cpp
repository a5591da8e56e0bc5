#include "scene/colmap.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cstring>
#include <fstream>
#include <sstream>

#include "core/error.h"
#include "core/fs.h"

namespace hgs {
namespace {

struct ModelInfo {
  int id;
  const char* name;
  int num_params;
};
// COLMAP's camera model table (src/colmap/sensor/models.h).
const ModelInfo kModels[] = {
    {0, "SIMPLE_PINHOLE", 3},
    {1, "PINHOLE", 4},
    {2, "SIMPLE_RADIAL", 4},
    {3, "RADIAL", 5},
    {4, "OPENCV", 8},
    {5, "OPENCV_FISHEYE", 8},
    {6, "FULL_OPENCV", 12},
    {7, "FOV", 5},
    {8, "SIMPLE_RADIAL_FISHEYE", 4},
    {9, "RADIAL_FISHEYE", 5},
    {10, "THIN_PRISM_FISHEYE", 12},
    {11, "RAD_TAN_THIN_PRISM_FISHEYE", 16},
};
const ModelInfo* model_by_id(int id) {
  for (auto& m : kModels)
    if (m.id == id) return &m;
  return nullptr;
}
const ModelInfo* model_by_name(const std::string& n) {
  for (auto& m : kModels)
    if (n == m.name) return &m;
  return nullptr;
}

// Bounds-checked little-endian reader over a file's bytes.
class Reader {
 public:
  Reader(std::filesystem::path p) : path_(std::move(p)), buf_(read_file_bytes(path_)) {}
  template <typename T>
  T get() {
    if (pos_ + sizeof(T) > buf_.size())
      fail("{}: truncated file (needed {} more bytes at offset {})", path_.string(), sizeof(T), pos_);
    T v;
    std::memcpy(&v, buf_.data() + pos_, sizeof(T));
    pos_ += sizeof(T);
    return v;
  }
  std::string cstring() {
    size_t start = pos_;
    while (pos_ < buf_.size() && buf_[pos_] != 0) ++pos_;
    if (pos_ >= buf_.size()) fail("{}: truncated file (unterminated image name at offset {})", path_.string(), start);
    std::string s(reinterpret_cast<const char*>(buf_.data() + start), pos_ - start);
    ++pos_;
    return s;
  }
  // Guards counts read from the file before allocating for them.
  void check_count(uint64_t count, size_t min_bytes_each, const char* what) {
    if (count > (buf_.size() - pos_) / std::max<size_t>(min_bytes_each, 1))
      fail("{}: corrupt file ({} count {} exceeds the file size)", path_.string(), what, count);
  }
  bool at_end() const { return pos_ == buf_.size(); }
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
  std::vector<uint8_t> buf_;
  size_t pos_ = 0;
};

// Image names become file names and appear in one-line error messages.
bool has_control_char(const std::string& s) {
  return std::any_of(s.begin(), s.end(), [](char c) { return static_cast<unsigned char>(c) < 0x20 || c == 0x7f; });
}

class Writer {
 public:
  template <typename T>
  void put(T v) {
    size_t n = buf.size();
    buf.resize(n + sizeof(T));
    std::memcpy(buf.data() + n, &v, sizeof(T));
  }
  void cstring(const std::string& s) {
    buf.insert(buf.end(), s.begin(), s.end());
    buf.push_back(0);
  }
  std::vector<uint8_t> buf;
};

}  // namespace

ColmapModel read_colmap_bin(const std::filesystem::path& dir) {
  ColmapModel m;
  {
    Reader r(dir / "cameras.bin");
    uint64_t n = r.get<uint64_t>();
    r.check_count(n, 24, "camera");
    for (uint64_t i = 0; i < n; ++i) {
      ColmapCamera c;
      c.id = r.get<int32_t>();
      int model_id = r.get<int32_t>();
      const ModelInfo* mi = model_by_id(model_id);
      if (!mi) fail("{}: unknown camera model id {} for camera {}", r.path().string(), model_id, c.id);
      c.model = mi->name;
      c.width = r.get<uint64_t>();
      c.height = r.get<uint64_t>();
      for (int k = 0; k < mi->num_params; ++k) c.params.push_back(r.get<double>());
      m.cameras[c.id] = c;
    }
    if (!r.at_end()) fail("{}: trailing bytes after {} cameras (corrupt file?)", r.path().string(), n);
  }
  {
    Reader r(dir / "images.bin");
    uint64_t n = r.get<uint64_t>();
    r.check_count(n, 64, "image");
    for (uint64_t i = 0; i < n; ++i) {
      ColmapImage im;
      im.id = r.get<int32_t>();
      for (int k = 0; k < 4; ++k) im.qvec[k] = r.get<double>();
      for (int k = 0; k < 3; ++k) im.tvec[k] = r.get<double>();
      im.camera_id = r.get<int32_t>();
      im.name = r.cstring();
      if (has_control_char(im.name)) fail("{}: image {} has a name with control characters", r.path().string(), im.id);
      uint64_t np = r.get<uint64_t>();
      r.check_count(np, 24, "point2D");
      im.xys.resize(np);
      im.point3d_ids.resize(np);
      for (uint64_t k = 0; k < np; ++k) {
        im.xys[k].x() = r.get<double>();
        im.xys[k].y() = r.get<double>();
        im.point3d_ids[k] = r.get<int64_t>();
      }
      if (!m.cameras.count(im.camera_id))
        fail("{}: image '{}' refers to camera {} which is not in cameras.bin", r.path().string(), im.name,
             im.camera_id);
      m.images.push_back(std::move(im));
    }
    if (!r.at_end()) fail("{}: trailing bytes after {} images (corrupt file?)", r.path().string(), n);
  }
  {
    Reader r(dir / "points3D.bin");
    uint64_t n = r.get<uint64_t>();
    r.check_count(n, 43, "point");
    m.points.resize(n);
    for (uint64_t i = 0; i < n; ++i) {
      ColmapPoint& p = m.points[i];
      p.id = r.get<uint64_t>();
      for (int k = 0; k < 3; ++k) p.xyz[k] = r.get<double>();
      for (int k = 0; k < 3; ++k) p.rgb[k] = r.get<uint8_t>();
      p.error = r.get<double>();
      uint64_t tl = r.get<uint64_t>();
      r.check_count(tl, 8, "track");
      p.track.resize(tl);
      for (uint64_t k = 0; k < tl; ++k) {
        p.track[k].first = r.get<int32_t>();
        p.track[k].second = r.get<int32_t>();
      }
    }
    if (!r.at_end()) fail("{}: trailing bytes after {} points (corrupt file?)", r.path().string(), n);
  }
  return m;
}

namespace {
// Yields the non-comment, non-empty lines of a COLMAP text file with their line numbers.
std::vector<std::pair<int, std::string>> text_lines(const std::filesystem::path& p) {
  std::istringstream in(read_file_text(p));
  std::vector<std::pair<int, std::string>> out;
  std::string line;
  int no = 0;
  while (std::getline(in, line)) {
    ++no;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    size_t s = line.find_first_not_of(" \t");
    if (s == std::string::npos || line[s] == '#') continue;
    out.emplace_back(no, line);
  }
  return out;
}
}  // namespace

ColmapModel read_colmap_txt(const std::filesystem::path& dir) {
  ColmapModel m;
  {
    auto path = dir / "cameras.txt";
    for (auto& [no, line] : text_lines(path)) {
      std::istringstream ss(line);
      ColmapCamera c;
      if (!(ss >> c.id >> c.model >> c.width >> c.height)) fail("{}:{}: malformed camera line", path.string(), no);
      const ModelInfo* mi = model_by_name(c.model);
      if (!mi) fail("{}:{}: unknown camera model '{}'", path.string(), no, c.model);
      double v;
      while (ss >> v) c.params.push_back(v);
      if (int(c.params.size()) != mi->num_params)
        fail("{}:{}: camera model {} needs {} parameters, found {}", path.string(), no, c.model, mi->num_params,
             c.params.size());
      m.cameras[c.id] = c;
    }
  }
  {
    auto path = dir / "images.txt";
    // Each image takes two lines; the keypoint line may be empty, so this reads raw lines, not text_lines().
    std::istringstream in(read_file_text(path));
    std::string line;
    int no = 0;
    bool expect_points = false;
    ColmapImage cur;
    while (std::getline(in, line)) {
      ++no;
      if (!line.empty() && line.back() == '\r') line.pop_back();
      if (!expect_points) {
        size_t s = line.find_first_not_of(" \t");
        if (s == std::string::npos || line[s] == '#') continue;
        std::istringstream ss(line);
        cur = ColmapImage{};
        if (!(ss >> cur.id >> cur.qvec[0] >> cur.qvec[1] >> cur.qvec[2] >> cur.qvec[3] >> cur.tvec[0] >> cur.tvec[1] >>
              cur.tvec[2] >> cur.camera_id))
          fail("{}:{}: malformed image line", path.string(), no);
        std::getline(ss >> std::ws, cur.name);
        while (!cur.name.empty() && (cur.name.back() == ' ' || cur.name.back() == '\t')) cur.name.pop_back();
        if (cur.name.empty()) fail("{}:{}: image line has no name", path.string(), no);
        if (has_control_char(cur.name)) fail("{}:{}: image name has control characters", path.string(), no);
        if (!m.cameras.count(cur.camera_id))
          fail("{}:{}: image '{}' refers to camera {} which is not in cameras.txt", path.string(), no, cur.name,
               cur.camera_id);
        expect_points = true;
      } else {
        std::istringstream ss(line);
        double x, y;
        int64_t pid;
        while (ss >> x >> y >> pid) {
          cur.xys.emplace_back(x, y);
          cur.point3d_ids.push_back(pid);
        }
        m.images.push_back(std::move(cur));
        expect_points = false;
      }
    }
    if (expect_points) m.images.push_back(std::move(cur));
  }
  {
    auto path = dir / "points3D.txt";
    for (auto& [no, line] : text_lines(path)) {
      std::istringstream ss(line);
      ColmapPoint p;
      int r, g, b;
      if (!(ss >> p.id >> p.xyz[0] >> p.xyz[1] >> p.xyz[2] >> r >> g >> b >> p.error))
        fail("{}:{}: malformed point line", path.string(), no);
      p.rgb[0] = r;
      p.rgb[1] = g;
      p.rgb[2] = b;
      int32_t a, c;
      while (ss >> a >> c) p.track.emplace_back(a, c);
      m.points.push_back(std::move(p));
    }
  }
  return m;
}

ColmapModel read_colmap(const std::filesystem::path& dir) {
  namespace fs = std::filesystem;
  if (!fs::is_directory(dir)) fail("{}: COLMAP model folder not found", dir.string());
  if (fs::exists(dir / "cameras.bin") || fs::exists(dir / "images.bin")) return read_colmap_bin(dir);
  if (fs::exists(dir / "cameras.txt") || fs::exists(dir / "images.txt")) return read_colmap_txt(dir);
  fail("{}: no COLMAP model (expected cameras/images/points3D .bin or .txt)", dir.string());
}

void write_colmap_bin(const std::filesystem::path& dir, const ColmapModel& m) {
  ensure_dir(dir);
  {
    Writer w;
    w.put<uint64_t>(m.cameras.size());
    for (auto& [id, c] : m.cameras) {
      const ModelInfo* mi = model_by_name(c.model);
      if (!mi) fail("unknown camera model '{}'", c.model);
      w.put<int32_t>(c.id);
      w.put<int32_t>(mi->id);
      w.put<uint64_t>(c.width);
      w.put<uint64_t>(c.height);
      for (double p : c.params) w.put<double>(p);
    }
    atomic_write_bytes(dir / "cameras.bin", w.buf.data(), w.buf.size());
  }
  {
    Writer w;
    w.put<uint64_t>(m.images.size());
    for (auto& im : m.images) {
      w.put<int32_t>(im.id);
      for (int k = 0; k < 4; ++k) w.put<double>(im.qvec[k]);
      for (int k = 0; k < 3; ++k) w.put<double>(im.tvec[k]);
      w.put<int32_t>(im.camera_id);
      w.cstring(im.name);
      w.put<uint64_t>(im.xys.size());
      for (size_t k = 0; k < im.xys.size(); ++k) {
        w.put<double>(im.xys[k].x());
        w.put<double>(im.xys[k].y());
        w.put<int64_t>(im.point3d_ids[k]);
      }
    }
    atomic_write_bytes(dir / "images.bin", w.buf.data(), w.buf.size());
  }
  {
    Writer w;
    w.put<uint64_t>(m.points.size());
    for (auto& p : m.points) {
      w.put<uint64_t>(p.id);
      for (int k = 0; k < 3; ++k) w.put<double>(p.xyz[k]);
      for (int k = 0; k < 3; ++k) w.put<uint8_t>(p.rgb[k]);
      w.put<double>(p.error);
      w.put<uint64_t>(p.track.size());
      for (auto& t : p.track) {
        w.put<int32_t>(t.first);
        w.put<int32_t>(t.second);
      }
    }
    atomic_write_bytes(dir / "points3D.bin", w.buf.data(), w.buf.size());
  }
}

void write_colmap_txt(const std::filesystem::path& dir, const ColmapModel& m) {
  ensure_dir(dir);
  std::string s = "# Camera list with one line of data per camera:\n#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n";
  for (auto& [id, c] : m.cameras) {
    s += fmt::format("{} {} {} {}", c.id, c.model, c.width, c.height);
    for (double p : c.params) s += fmt::format(" {:.17g}", p);
    s += "\n";
  }
  atomic_write_text(dir / "cameras.txt", s);
  s = "# Image list with two lines of data per image:\n#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n#   "
      "POINTS2D[] as (X, Y, POINT3D_ID)\n";
  for (auto& im : m.images) {
    s += fmt::format("{} {:.17g} {:.17g} {:.17g} {:.17g} {:.17g} {:.17g} {:.17g} {} {}\n", im.id, im.qvec[0],
                     im.qvec[1], im.qvec[2], im.qvec[3], im.tvec[0], im.tvec[1], im.tvec[2], im.camera_id, im.name);
    for (size_t k = 0; k < im.xys.size(); ++k)
      s += fmt::format("{}{:.17g} {:.17g} {}", k ? " " : "", im.xys[k].x(), im.xys[k].y(), im.point3d_ids[k]);
    s += "\n";
  }
  atomic_write_text(dir / "images.txt", s);
  s = "# 3D point list with one line of data per point:\n#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as "
      "(IMAGE_ID, POINT2D_IDX)\n";
  for (auto& p : m.points) {
    s += fmt::format("{} {:.17g} {:.17g} {:.17g} {} {} {} {:.17g}", p.id, p.xyz[0], p.xyz[1], p.xyz[2], p.rgb[0],
                     p.rgb[1], p.rgb[2], p.error);
    for (auto& t : p.track) s += fmt::format(" {} {}", t.first, t.second);
    s += "\n";
  }
  atomic_write_text(dir / "points3D.txt", s);
}

void require_pinhole(const ColmapCamera& c, const std::string& where, double& fx, double& fy, double& cx, double& cy) {
  if (c.model == "PINHOLE") {
    fx = c.params[0];
    fy = c.params[1];
    cx = c.params[2];
    cy = c.params[3];
  } else if (c.model == "SIMPLE_PINHOLE") {
    fx = fy = c.params[0];
    cx = c.params[1];
    cy = c.params[2];
  } else {
    fail("{}: camera {} uses the {} model; hgs needs PINHOLE or SIMPLE_PINHOLE: run `colmap image_undistorter` first",
         where, c.id, c.model);
  }
}

Eigen::Matrix3d qvec_to_rotmat(const Eigen::Vector4d& q) {
  Eigen::Quaterniond qq(q[0], q[1], q[2], q[3]);
  return qq.normalized().toRotationMatrix();
}

Eigen::Vector4d rotmat_to_qvec(const Eigen::Matrix3d& R) {
  Eigen::Quaterniond q(R);
  q.normalize();
  if (q.w() < 0) q.coeffs() *= -1;
  return {q.w(), q.x(), q.y(), q.z()};
}

std::filesystem::path colmap_model_dir(const std::filesystem::path& scene) {
  const std::filesystem::path sparse = scene / "sparse";
  if (std::filesystem::is_directory(sparse / "0")) return sparse / "0";
  std::error_code ec;
  const bool cameras = std::filesystem::exists(sparse / "cameras.bin", ec);
  if (ec) fail("{}: cannot access ({})", (sparse / "cameras.bin").string(), ec.message());
  if (!std::filesystem::is_directory(sparse) || !cameras)
    fail("{}: no COLMAP model (expected sparse/0/ with cameras, images, points3D)", scene.string());
  return sparse;
}

}  // namespace hgs
