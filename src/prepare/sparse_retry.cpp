// Records of the retries of a sparse capture (sparse_retry.h).
#include "prepare/sparse_retry.h"

#include <fmt/format.h>

#include <algorithm>

#include "core/error.h"

namespace hgs::prepare {
namespace fs = std::filesystem;

MappingInfo map_and_summarize(const fs::path& colmap, const fs::path& input_dir, const fs::path& work,
                              const std::vector<std::string>& names, const PoseOptions& opt, const std::string& sparse,
                              const fs::path& scene, const std::string& settings) {
  const int n = int(names.size());
  const fs::path best = map_poses(colmap, input_dir, work, n, opt, sparse);
  MappingInfo m;
  m.matcher = opt.matcher, m.settings = settings, m.images = n;
  if (best.empty()) {
    m.dropped = names;
    return m;
  }
  const PoseSummary s = summarize_model(best, names);
  m.registered = s.registered, m.dropped = s.dropped, m.cameras = s.cameras, m.points = s.points;
  m.mean_reprojection_error_px = s.mean_reprojection_error, m.mean_track_length = s.mean_track_length;
  for (const auto& e : fs::directory_iterator(work / sparse)) m.models += e.is_directory();
  m.model_path = model_record(best, scene);
  return m;
}

bool registered_enough(const MappingInfo& m) { return m.registered > 0 && 2 * m.registered >= m.images; }

MappingInfo keep_better(const MappingInfo& kept, const MappingInfo& retry) {
  MappingInfo r = retry.registered > kept.registered ? retry : kept;
  r.retried = kept.retried;
  r.retried.push_back(fmt::format("{}: {} of {}", retry.settings, retry.registered, retry.images));
  return r;
}

void check_registration(const MappingInfo& m, bool allow_partial) {
  const std::string tried = m.retried.empty() ? "" : fmt::format(" (retried: {})", fmt::join(m.retried, "; "));
  const std::string matcher = m.matcher == "exhaustive" ? "" : ", try --matcher exhaustive";
  if (m.model_path.empty() && m.model.empty())
    fail(
        "colmap mapper made no model from {} images{}: too few matches between the images; take more overlapping "
        "photos with more texture{}",
        m.images, tried, matcher);
  if (allow_partial || registered_enough(m)) return;
  fail(
      "COLMAP registered only {} of {} images ({:.0f} %; dropped {}{}){}: the photos overlap too little or lack "
      "texture; take more overlapping photos{}, or keep going with the registered ones with --allow-partial",
      m.registered, m.images, 100.0 * m.registered / std::max(1, m.images),
      fmt::join(m.dropped.begin(), m.dropped.begin() + std::min<size_t>(m.dropped.size(), 5), ", "),
      m.dropped.size() > 5 ? ", ..." : "", tried, matcher);
}

}  // namespace hgs::prepare
