// Reducer: how the trainer combines one step's gradients across processes. A step sees a global batch of views:
// `batch` views on each of size() processes (MPI ranks, mpi/session.h). Every process sums its own views'
// contributions in view order, then sum() adds the processes' partial sums in rank order, so R ranks of one view
// each give bit for bit what one process with --batch R gives (it adds the same numbers in the same order).
// The base class is the single process: nothing to combine.
#pragma once
#include <cstddef>
#include <cstdint>
#include <vector>

namespace hgs::train {

// What the reductions of a run cost (this process).
struct CommStats {
  double bytes_sent = 0;  // payload bytes this process handed to MPI (all collectives)
  double ms = 0;          // wall time inside the collectives (includes waiting for slower ranks)
  long calls = 0;
};

class Reducer {
 public:
  virtual ~Reducer() = default;
  virtual int rank() const { return 0; }
  virtual int size() const { return 1; }
  // data [n] := the sum over ranks of every rank's data [n], added in rank order: ((d_0 + d_1) + d_2) + ...
  virtual void sum(float* /*data*/, size_t /*n*/) {}
  // data [n] := the element-wise maximum over ranks (exact, order-free).
  virtual void max(float* /*data*/, size_t /*n*/) {}
  // Every rank's bytes, in rank order (this rank's included).
  virtual std::vector<std::vector<uint8_t>> gather(const std::vector<uint8_t>& mine) { return {mine}; }
  // Every rank gets rank 0's bytes.
  virtual void broadcast(std::vector<uint8_t>& /*bytes*/) {}
  CommStats stats;
};

}  // namespace hgs::train
