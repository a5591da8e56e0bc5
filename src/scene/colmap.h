// COLMAP sparse model I/O: cameras, images and points3D in the binary (.bin) and text (.txt) formats, read
// and written byte-compatibly with COLMAP itself. Only the pinhole models are usable by hgs (see
// `require_pinhole`); other models are parsed so that the error can name them.
#pragma once
#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

namespace hgs {

struct ColmapCamera {
  int id = 0;
  std::string model;  // "PINHOLE", "SIMPLE_PINHOLE", "OPENCV", ...
  uint64_t width = 0, height = 0;
  std::vector<double> params;  // model-specific
};

struct ColmapImage {
  int id = 0;
  Eigen::Vector4d qvec{1, 0, 0, 0};  // world-to-camera rotation, (w, x, y, z)
  Eigen::Vector3d tvec{0, 0, 0};     // world-to-camera translation
  int camera_id = 0;
  std::string name;                  // relative to images/, may contain sub-folders
  std::vector<Eigen::Vector2d> xys;  // [P, 2] keypoints
  std::vector<int64_t> point3d_ids;  // [P], -1 when unmatched
};

struct ColmapPoint {
  uint64_t id = 0;
  Eigen::Vector3d xyz{0, 0, 0};
  uint8_t rgb[3] = {0, 0, 0};
  double error = 0;
  std::vector<std::pair<int32_t, int32_t>> track;  // (image_id, point2D_idx)
};

struct ColmapModel {
  std::map<int, ColmapCamera> cameras;
  std::vector<ColmapImage> images;  // in file order
  std::vector<ColmapPoint> points;
};

// The COLMAP model of a scene folder: SCENE/sparse/0/, or SCENE/sparse/ itself when it holds cameras.bin.
// Fails naming the scene when neither is there.
std::filesystem::path colmap_model_dir(const std::filesystem::path& scene);

// Reads SPARSE_DIR/{cameras,images,points3D}.bin, or the .txt trio when the .bin files are absent.
ColmapModel read_colmap(const std::filesystem::path& sparse_dir);
ColmapModel read_colmap_bin(const std::filesystem::path& sparse_dir);
ColmapModel read_colmap_txt(const std::filesystem::path& sparse_dir);
void write_colmap_bin(const std::filesystem::path& sparse_dir, const ColmapModel& m);
void write_colmap_txt(const std::filesystem::path& sparse_dir, const ColmapModel& m);

// Pinhole intrinsics of a camera (fx, fy, cx, cy). Fails for non-pinhole models with advice to undistort.
void require_pinhole(const ColmapCamera& cam, const std::string& where, double& fx, double& fy, double& cx, double& cy);

Eigen::Matrix3d qvec_to_rotmat(const Eigen::Vector4d& q);  // (w, x, y, z), normalised first
Eigen::Vector4d rotmat_to_qvec(const Eigen::Matrix3d& R);

}  // namespace hgs
