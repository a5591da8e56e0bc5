// Data-parallel training over MPI (`mpirun -np R hgs train ...`): the session (MPI_Init / MPI_Finalize when the
// process was started by an MPI launcher) and the Reducer that combines a step's gradients across the ranks
// (train/reducer.h). No networking of our own: the collectives are MPI's (Alltoallv, Allgatherv, Allreduce).
// Built without MPI (no libopenmpi-dev at configure time), a process started by mpirun with more than one rank
// stops with a one-line error; a single process never needs MPI.
#pragma once
#include <memory>
#include <string>

#include "train/reducer.h"

namespace hgs::mpi {

// True when an MPI launcher started this process (OpenMPI's, MPICH's or PMIx's environment).
bool launched_by_mpi();
// Ranks started on this machine by the launcher (1 without one): for the default thread count per rank.
int local_ranks();

// One per process: initialises MPI when launched by an MPI launcher, finalises on a normal exit. A process
// leaving by an exception does not finalise: it exits non-zero and the launcher ends the other ranks.
class Session {
 public:
  Session();
  ~Session();
  Session(const Session&) = delete;
  Session& operator=(const Session&) = delete;
  int rank() const;
  int size() const;
  // The reducer of the world communicator (a single-process one when size() == 1).
  train::Reducer& reducer();

 private:
  bool initialised_ = false;
  std::unique_ptr<train::Reducer> reducer_;
};

}  // namespace hgs::mpi
