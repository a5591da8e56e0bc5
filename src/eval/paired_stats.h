// Statistics of ablation tables (`hgs ablate`, bench/table3_pool.py computes the same in Python): the mean and
// sample standard deviation of a row's runs, and paired differences between two rows with a 95 % interval
// clustered by scene. A scene's training seeds share its images, masks and features, so its runs are not
// independent: the differences are averaged over the seeds of each scene first, and the interval is Student's t
// over those scene means (n = scenes, n - 1 degrees of freedom).
#pragma once
#include <cmath>
#include <string>
#include <utility>
#include <vector>

namespace hgs::eval {

// Mean and sample standard deviation (n - 1) of the finite values; NaN mean with none, NaN std with one.
std::pair<double, double> mean_std(const std::vector<double>& v);

// Student's t quantile t_{0.975, dof} for a 95 % interval of a mean: a fixed table for dof 1..30, then the normal
// 1.96 as the limit; NaN for dof < 1.
double t975(int dof);

struct ScenePaired {
  double mean = NAN;  // mean over the scenes of each scene's mean difference
  double half = NAN;  // half-width of its 95 % interval: t975(scenes - 1) * sd(scene means) / sqrt(scenes)
  int scenes = 0;     // scenes with at least one finite difference (n)
  int runs = 0;       // finite differences, every (scene, seed)
};
// Paired differences of two rows, one entry per (scene, seed) run: {scene, row A - row B}. Non-finite
// differences are left out. With one scene the interval is undefined (NaN).
ScenePaired paired_by_scene(const std::vector<std::pair<std::string, double>>& diffs);

}  // namespace hgs::eval
