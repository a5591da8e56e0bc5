// MPI reducer. sum() is deterministic and follows rank order, so that R ranks of one view each equal one process
// with --batch R bit for bit: a reduce-scatter written with MPI_Alltoallv (rank k receives every rank's slice k
// and adds the slices in rank order) followed by MPI_Allgatherv of the summed slices. Each rank sends
// 2 (R - 1) / R of the buffer, as a ring allreduce does; MPI_Allreduce itself is not used for sums because its
// order of addition is the library's choice (it may depend on R, the message size and the algorithm picked).
#include "mpi/session.h"

#include <algorithm>
#include <chrono>
#include <climits>
#include <cstdlib>
#include <vector>

#include "core/error.h"
#include "core/sanitizers.h"

#ifdef HGS_HAVE_MPI
#define OMPI_SKIP_MPICXX 1  // the C API only: OpenMPI's and MPICH's deprecated C++ bindings need libmpi_cxx
#define MPICH_SKIP_MPICXX 1
#include <mpi.h>
#endif

namespace hgs::mpi {

bool launched_by_mpi() {
  for (const char* v : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_RANK", "MPI_LOCALNRANKS"})
    if (std::getenv(v)) return true;
  return false;
}

int local_ranks() {
  for (const char* v : {"OMPI_COMM_WORLD_LOCAL_SIZE", "MPI_LOCALNRANKS"})
    if (const char* s = std::getenv(v)) {
      const int n = std::atoi(s);
      if (n > 0) return n;
    }
  return 1;
}

#ifdef HGS_HAVE_MPI
namespace {

class MpiReducer final : public train::Reducer {
 public:
  MpiReducer() {
    MPI_Comm_rank(MPI_COMM_WORLD, &rank_);
    MPI_Comm_size(MPI_COMM_WORLD, &size_);
  }
  int rank() const override { return rank_; }
  int size() const override { return size_; }

  void sum(float* data, size_t n) override {
    const auto t0 = std::chrono::steady_clock::now();
    // Segments of at most 2^26 floats keep MPI's int counts and the receive buffer bounded.
    constexpr size_t kSeg = size_t(1) << 26;
    for (size_t s0 = 0; s0 < n; s0 += kSeg) sum_segment(data + s0, std::min(kSeg, n - s0));
    finish(t0);
  }

  void max(float* data, size_t n) override {
    const auto t0 = std::chrono::steady_clock::now();
    for (size_t s0 = 0; s0 < n; s0 += size_t(INT_MAX / 2)) {
      const int c = int(std::min(size_t(INT_MAX / 2), n - s0));
      MPI_Allreduce(MPI_IN_PLACE, data + s0, c, MPI_FLOAT, MPI_MAX, MPI_COMM_WORLD);
      stats.bytes_sent += 4.0 * c * 2 * (size_ - 1) / size_;  // as a ring would send it
    }
    finish(t0);
  }

  std::vector<std::vector<uint8_t>> gather(const std::vector<uint8_t>& mine) override {
    const auto t0 = std::chrono::steady_clock::now();
    if (mine.size() > size_t(INT_MAX)) fail("mpi: {} bytes to gather from one rank (at most 2 GiB)", mine.size());
    int len = int(mine.size());
    std::vector<int> lens(size_), displs(size_);
    MPI_Allgather(&len, 1, MPI_INT, lens.data(), 1, MPI_INT, MPI_COMM_WORLD);
    long total = 0;
    for (int r = 0; r < size_; ++r) {
      displs[r] = int(total);
      total += lens[r];
      if (total > INT_MAX) fail("mpi: more than 2 GiB to gather over the ranks");
    }
    std::vector<uint8_t> all(size_t(total) + 1);
    MPI_Allgatherv(mine.data(), len, MPI_BYTE, all.data(), lens.data(), displs.data(), MPI_BYTE, MPI_COMM_WORLD);
    std::vector<std::vector<uint8_t>> out(size_);
    for (int r = 0; r < size_; ++r) out[r].assign(all.begin() + displs[r], all.begin() + displs[r] + lens[r]);
    stats.bytes_sent += 4.0 * (size_ - 1) + double(len) * (size_ - 1);
    finish(t0);
    return out;
  }

  void broadcast(std::vector<uint8_t>& bytes) override {
    const auto t0 = std::chrono::steady_clock::now();
    long len = long(bytes.size());
    MPI_Bcast(&len, 1, MPI_LONG, 0, MPI_COMM_WORLD);
    if (len > INT_MAX) fail("mpi: more than 2 GiB to broadcast");
    bytes.resize(size_t(len));
    MPI_Bcast(bytes.data(), int(len), MPI_BYTE, 0, MPI_COMM_WORLD);
    if (rank_ == 0) stats.bytes_sent += double(len) * (size_ - 1);
    finish(t0);
  }

 private:
  int rank_ = 0, size_ = 1;
  std::vector<int> send_counts_, send_displs_, recv_counts_, recv_displs_;
  std::vector<float> recv_, mine_;

  void finish(std::chrono::steady_clock::time_point t0) {
    stats.ms += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    stats.calls += 1;
  }

  void sum_segment(float* data, size_t n) {
    const int R = size_;
    auto begin = [&](int k) { return int(n * size_t(k) / size_t(R)); };  // slice k = [begin(k), begin(k + 1))
    send_counts_.resize(R);
    send_displs_.resize(R);
    recv_counts_.resize(R);
    recv_displs_.resize(R);
    const int my0 = begin(rank_), my_len = begin(rank_ + 1) - my0;
    for (int k = 0; k < R; ++k) {
      send_displs_[k] = begin(k);
      send_counts_[k] = begin(k + 1) - begin(k);
      recv_counts_[k] = my_len;
      recv_displs_[k] = k * my_len;
    }
    recv_.resize(size_t(R) * my_len + 1);
    MPI_Alltoallv(data, send_counts_.data(), send_displs_.data(), MPI_FLOAT, recv_.data(), recv_counts_.data(),
                  recv_displs_.data(), MPI_FLOAT, MPI_COMM_WORLD);
    // Slice rank_ of the sum, added in rank order.
    mine_.assign(recv_.begin(), recv_.begin() + my_len);
    for (int k = 1; k < R; ++k) {
      const float* x = recv_.data() + size_t(k) * my_len;
      for (int e = 0; e < my_len; ++e) mine_[e] += x[e];
    }
    MPI_Allgatherv(mine_.data(), my_len, MPI_FLOAT, data, send_counts_.data(), send_displs_.data(), MPI_FLOAT,
                   MPI_COMM_WORLD);
    stats.bytes_sent += 4.0 * (double(n) - my_len) + 4.0 * double(my_len) * (R - 1);
  }
};

}  // namespace

namespace {
bool mpi_initialised = false;  // by this process (read by __lsan_is_turned_off below)
}  // namespace

Session::Session() {
  if (launched_by_mpi()) {
    int done = 0;
    MPI_Initialized(&done);
    if (!done) {
      int provided = 0;
      // Only the main thread calls MPI (OpenMP threads never do).
      MPI_Init_thread(nullptr, nullptr, MPI_THREAD_FUNNELED, &provided);
      initialised_ = true;
      mpi_initialised = true;
    }
    reducer_ = std::make_unique<MpiReducer>();
  } else {
    reducer_ = std::make_unique<train::Reducer>();
  }
}

Session::~Session() {
  if (initialised_ && std::uncaught_exceptions() == 0) MPI_Finalize();
}

}  // namespace hgs::mpi

#if HGS_SANITIZE_ADDRESS
// LeakSanitizer's hook (sanitizer/lsan_interface.h): its exit check is skipped in a process that initialised MPI.
// OpenMPI 4.1 keeps state past MPI_Finalize in plugins it has dlclose()d, so no suppression can name their frames;
// every process that does not run MPI (single-process training included) keeps the check. Sanitizer builds only.
extern "C" int __lsan_is_turned_off() { return hgs::mpi::mpi_initialised ? 1 : 0; }
#endif

namespace hgs::mpi {

#else  // built without MPI

Session::Session() {
  if (launched_by_mpi()) {
    const char* n = std::getenv("OMPI_COMM_WORLD_SIZE");
    if (!n) n = std::getenv("PMI_SIZE");
    if (n && std::atoi(n) > 1)
      fail(
          "this hgs was built without MPI (libopenmpi-dev was missing at configure time: run scripts/setup, then "
          "rebuild): it cannot train on {} ranks",
          n);
  }
  reducer_ = std::make_unique<train::Reducer>();
}

Session::~Session() = default;

#endif

int Session::rank() const { return reducer_->rank(); }
int Session::size() const { return reducer_->size(); }
train::Reducer& Session::reducer() { return *reducer_; }

}  // namespace hgs::mpi
