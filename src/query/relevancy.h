// LERF's relevancy score of an embedding for a text query against canonical ("negative") phrases such as
// "object", "things", "stuff", "texture" (Kerr et al. 2023):
//   s_q = cos(e, q), s_i = cos(e, c_i),
//   p_i = exp(T s_q) / (exp(T s_q) + exp(T s_i)) = 1 / (1 + exp(T (s_i - s_q))),   T = 10,
//   relevancy = min_i p_i  (in (0, 1); 0.5 means "as close to the query as to the closest canonical phrase").
// Cosines of a zero vector are taken as 0.
#pragma once
#include <cstddef>
#include <vector>

namespace hgs::query {

constexpr float kLerfTemperature = 10.f;

// Cosine similarity of two D-vectors (0 if either is zero).
float cosine(const float* a, const float* b, int dim);

// Fails with a one-line error unless there is at least one canonical phrase and each is [dim] (dim > 0).
void check_canonical(const std::vector<std::vector<float>>& canonical, int dim);

// The relevancy from the cosines: sq = cos(e, query), sc [m] = cos(e, canonical_i).
float lerf_relevancy_from_cosines(double sq, const double* sc, size_t m, float temperature = kLerfTemperature);

// Relevancy of one embedding `e` [D] for `query` [D] against `canonical` (each [D], at least one).
float lerf_relevancy(const float* e, const float* query, const std::vector<std::vector<float>>& canonical, int dim,
                     float temperature = kLerfTemperature);

// The same for a whole map: features [N, stride] whose first D columns are the embeddings (stride 0 = D; e.g.
// N = H * W) -> relevancy [N]. Multi-threaded (OpenMP).
std::vector<float> lerf_relevancy_map(const float* features, size_t n, int dim, const float* query,
                                      const std::vector<std::vector<float>>& canonical,
                                      float temperature = kLerfTemperature, int stride = 0);

}  // namespace hgs::query
