// Paired differences clustered by scene: group the runs by scene, average each scene's differences over its
// seeds, then a one-sample t-interval over the scene means.
#include "eval/paired_stats.h"

#include <cmath>
#include <map>

namespace hgs::eval {

std::pair<double, double> mean_std(const std::vector<double>& v) {
  double s = 0;
  int n = 0;
  for (double x : v)
    if (std::isfinite(x)) s += x, ++n;
  if (n == 0) return {NAN, NAN};
  const double m = s / n;
  double ss = 0;
  for (double x : v)
    if (std::isfinite(x)) ss += (x - m) * (x - m);
  return {m, n > 1 ? std::sqrt(ss / (n - 1)) : NAN};
}

double t975(int dof) {
  static const double t[30] = {12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228,
                               2.201,  2.179, 2.160, 2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086,
                               2.080,  2.074, 2.069, 2.064, 2.060, 2.056, 2.052, 2.048, 2.045, 2.042};
  return dof < 1 ? NAN : dof <= 30 ? t[dof - 1] : 1.96;
}

ScenePaired paired_by_scene(const std::vector<std::pair<std::string, double>>& diffs) {
  std::map<std::string, std::vector<double>> by_scene;
  ScenePaired p;
  for (const auto& [scene, d] : diffs)
    if (std::isfinite(d)) by_scene[scene].push_back(d), ++p.runs;
  std::vector<double> means;
  for (const auto& [scene, d] : by_scene) means.push_back(mean_std(d).first);
  p.scenes = int(means.size());
  if (means.empty()) return p;
  const auto [m, sd] = mean_std(means);
  p.mean = m;
  p.half = p.scenes > 1 ? t975(p.scenes - 1) * sd / std::sqrt(double(p.scenes)) : NAN;
  return p;
}

}  // namespace hgs::eval
