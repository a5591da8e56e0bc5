// k nearest neighbours of 3D points among themselves, with a k-d tree (median splits, leaf size 8) built
// once and queried in parallel (OpenMP). Used for the 3DGS scale initialisation on up to millions of points.
#pragma once
#include <Eigen/Core>
#include <vector>

namespace hgs {

// For every point, the mean squared Euclidean distance to its k nearest other points (k <= 16; fewer when
// the cloud has fewer than k + 1 points). Returns [P].
std::vector<float> knn_mean_sq_dist(const std::vector<Eigen::Vector3f>& points,  // [P, 3]
                                    int k);

// Indices of the k nearest other points of every point, nearest first: [P, k] (-1 padding when P <= k).
std::vector<int> knn_indices(const std::vector<Eigen::Vector3f>& points, int k);

}  // namespace hgs
