// The pose stages of `hgs prepare`, on Debian's COLMAP 3.8 (`colmap`, CPU SIFT):
//   features   feature_extractor into WORK/database.db; one camera per image size (images of one size share a
//              camera: one run per size with single_camera and an image list, so mixed captures keep one
//              intrinsic calibration per device and image names stay flat);
//   matching   exhaustive_matcher, sequential_matcher (ordered frames: overlap 10 + quadratic overlap) or
//              vocab_tree_matcher (needs a vocabulary tree file: COLMAP's are downloads, not in Debian);
//              "auto" = sequential for video frames, exhaustive up to kExhaustiveUpTo photos, above it
//              sequential by file name (cameras name photos in shooting order) or a vocabulary tree when one is
//              given. COLMAP's CPU matcher costs ~0.5 s per pair at 2048 features on one core (docs/capture.md):
//              exhaustive over 80 photos is 3240 pairs, sequential about 10 per photo;
//   mapping    mapper into WORK/sparse/N, then the model with the most registered images is kept;
//   undistort  image_undistorter to PINHOLE: SCENE/images/ and SCENE/sparse/0/, what `hgs train` reads.
// Each runs colmap with a progress bar parsed from its log (WORK/logs/<stage>.log).
#pragma once
#include <algorithm>
#include <filesystem>
#include <string>
#include <vector>

namespace hgs::prepare {

inline constexpr int kExhaustiveUpTo = 40;

struct PoseOptions {
  std::string colmap = "colmap";  // program name or path
  std::string matcher = "auto";   // auto | exhaustive | sequential | vocab-tree
  std::string vocab_tree;         // vocabulary tree file (vocab-tree matcher)
  std::string camera_model = "SIMPLE_RADIAL";
  int max_features = 4096;  // SIFT features per image
  bool ordered = false;     // input images are video frames in order
  bool progress = true;
  // COLMAP's wide-baseline settings (the retries of a sparse capture, see below): wide_features(max_features)
  // features, affine-covariant with domain-size pooling; guided matching; mapper initialisation and
  // registration with fewer inliers and a smaller triangulation angle (kWideMapperArgs).
  bool wide_baseline = false;
};

// When fewer than half the images register, the pose stages retry on their own, in order, until half register:
//   retry_mapping   the mapper again on the same matches with the wide-baseline mapper options (cheap);
//   retry_features  features, matching and mapping again in WORK/retry/ with every wide-baseline setting.
// The model with the most registered images is kept. On a capture of 20 goldcape photos 18 degrees apart
// COLMAP's defaults register 3; these settings by hand, 13 (issue 60); hgs prepare 13 of 21 (docs/capture.md).
// Features: twice --max-features (8192 at the default, what the by-hand run used), so that a user who bounded the
// cost of features bounds the retry's too.
inline int wide_features(int max_features) { return std::min(2 * max_features, 65536); }
inline const std::vector<std::string> kWideMapperArgs = {"--Mapper.init_min_num_inliers",     "50",
                                                         "--Mapper.abs_pose_min_num_inliers", "15",
                                                         "--Mapper.init_min_tri_angle",       "8"};

// What a reconstruction holds, for the report.
struct PoseSummary {
  int images = 0;                    // input images
  int registered = 0;                // in the kept model
  std::vector<std::string> dropped;  // input images not registered, sorted
  int models = 0;                    // models the mapper made
  int cameras = 0;
  int points = 0;
  double mean_reprojection_error = 0;  // px, mean over points of COLMAP's per-point error
  double mean_track_length = 0;        // observations per point
  std::string matcher;                 // the matcher that ran
};

// The matcher "auto" resolves to for `n` images.
std::string choose_matcher(const PoseOptions& opt, int n);

void extract_features(const std::filesystem::path& colmap, const std::filesystem::path& input_dir,
                      const std::filesystem::path& work, const PoseOptions& opt);
void match_features(const std::filesystem::path& colmap, const std::filesystem::path& work, const std::string& matcher,
                    int n_images, const PoseOptions& opt);
// Runs the mapper on WORK/database.db into WORK/<sparse> (log WORK/logs/<sparse>.log); returns the folder of the
// largest model (WORK/<sparse>/N), or an empty path when the mapper made none.
std::filesystem::path map_poses(const std::filesystem::path& colmap, const std::filesystem::path& input_dir,
                                const std::filesystem::path& work, int n_images, const PoseOptions& opt,
                                const std::string& sparse = "sparse");
// Undistorts `model` into SCENE/images and SCENE/sparse/0 (replacing earlier ones only once complete).
void undistort(const std::filesystem::path& colmap, const std::filesystem::path& input_dir,
               const std::filesystem::path& model, const std::filesystem::path& work,
               const std::filesystem::path& scene, const PoseOptions& opt);

// Statistics of a COLMAP model folder against the input image names.
PoseSummary summarize_model(const std::filesystem::path& model, const std::vector<std::string>& input_names);

}  // namespace hgs::prepare
