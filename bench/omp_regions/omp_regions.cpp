// LD_PRELOAD library for bench/project_threads.py: what a run on one thread says about T threads, region by
// region. It wraps libgomp's entry points (GCC's OpenMP: GOMP_parallel for every parallel region and
// GOMP_parallel_loop_nonmonotonic_dynamic for a combined `parallel for schedule(dynamic)`, the dynamic loops'
// start / next calls, GOMP_single_start and GOMP_barrier) and records, per region (keyed by its outlined
// function), the calls, the wall time, the time in `single` blocks (serial inside the region) and the duration of
// every chunk its dynamic loops hand out. At each loop's end it simulates how schedule(dynamic) would hand the
// same chunks, in the same order, to T = 2, 4, 8, 16, 32 threads (each to the thread that frees first) and keeps
// the makespan. The rest of a region's time (static loops, code outside loops) is what the projection divides by
// T: it cannot see memory bandwidth, shared caches, clock speed under load or the barriers' cost.
//
// With HGS_PLAN_THREADS=T and HGS_PLAN_RANGES=lo-hi[,lo-hi...] (hex offsets of functions in the executable, from
// nm), omp_get_max_threads() called from inside those functions returns T, so that code which cuts its work by the
// thread count (the object losses' bands, SSIM's bands) cuts it as for T threads, while every region still runs
// on one thread (their num_threads is forced to 1). Other callers see the real value: per-thread partial sums sized
// by it must match the threads that run.
//
// For one-thread runs only (its tables are plain globals, not shared safely between threads), except with
// HGS_REGIONS_WALL=1: then it records the regions' wall times and the gaps between them alone, at any thread count
// (what project_threads.py --measure compares with the projection). The team's threads then pass through every
// wrapper (dynamic loops, single, barrier) untouched, and so does a region started inside another (a nested one,
// omp_get_level() > 0), so that only the thread outside every region writes the tables.
//
// Written by hand: no Debian package times OpenMP regions of GCC's runtime (OMPT, the standard interface, is
// LLVM's libomp only). Output at exit to HGS_REGIONS_OUT.<pid>, one line per region:
//   offset calls seconds single_seconds dynamic_seconds chunks makespan_T2 .. makespan_T32 after_seconds symbol
// (after: the time from the region's end to the start of the next region, the serial code between them).
#include <dlfcn.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <ctime>

namespace {

constexpr int kMaxRegions = 4096, kMaxChunks = 1 << 18, kSims = 5;
constexpr int kSimThreads[kSims] = {2, 4, 8, 16, 32};

struct Region {
  void* fn = nullptr;
  long calls = 0;
  double seconds = 0, single = 0, dynamic = 0, makespan[kSims] = {};
  long chunks = 0;
  double after = 0;  // the time from the end of this region to the start of the next (serial code between them)
};
Region regions[kMaxRegions];
int num_regions = 0, depth = 0, current = -1, last_region = -1;
double last_end = -1;
double chunk[kMaxChunks];
int num_chunks = 0;
double chunk_start = -1, single_start = -1;

double now() {
  timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

template <class F>
F real(const char* name) {
  return reinterpret_cast<F>(dlsym(RTLD_NEXT, name));
}

// The current dynamic loop's chunks, handed to T threads in order (each to the thread that frees first).
void close_loop() {
  if (current >= 0 && num_chunks > 0) {
    Region& r = regions[current];
    for (int i = 0; i < num_chunks; ++i) r.dynamic += chunk[i];
    r.chunks += num_chunks;
    for (int s = 0; s < kSims; ++s) {
      double busy[32] = {};
      const int T = kSimThreads[s];
      for (int i = 0; i < num_chunks; ++i) {
        int b = 0;
        for (int t = 1; t < T; ++t)
          if (busy[t] < busy[b]) b = t;
        busy[b] += chunk[i];
      }
      double m = 0;
      for (int t = 0; t < T; ++t) m = busy[t] > m ? busy[t] : m;
      r.makespan[s] += m;
    }
  }
  num_chunks = 0;
}

int plan_threads() {
  static int plan = -1;
  if (plan < 0) {
    const char* e = getenv("HGS_PLAN_THREADS");
    plan = e ? atoi(e) : 0;
  }
  return plan;
}

bool wall_only() {
  static int wall = -1;
  if (wall < 0) {
    const char* e = getenv("HGS_REGIONS_WALL");
    wall = e && e[0] == '1';
  }
  return wall;
}

// One parallel region (outlined function fn) run by `call` (the runtime's entry point with its arguments).
template <class Call>
void region(void (*fn)(void*), Call call) {
  static auto level = real<int (*)()>("omp_get_level");
  if (wall_only() && level() > 0) {  // started inside a region, by a thread of its team
    call();
    return;
  }
  if (depth > 0) {
    call();
    return;
  }
  int i = 0;
  while (i < num_regions && regions[i].fn != reinterpret_cast<void*>(fn)) ++i;
  if (i == num_regions && num_regions < kMaxRegions) regions[num_regions++].fn = reinterpret_cast<void*>(fn);
  if (i >= kMaxRegions) {
    call();
    return;
  }
  const int outer = current;
  current = i;
  chunk_start = -1;
  const double t0 = now();
  if (last_region >= 0) regions[last_region].after += t0 - last_end;
  ++depth;
  call();
  --depth;
  close_loop();
  last_end = now();
  if (single_start >= 0) regions[i].single += last_end - single_start;  // a single block ending the region (no
  single_start = -1;                                                    // barrier call of its own)
  last_region = i;
  regions[i].seconds += last_end - t0;
  regions[i].calls += 1;
  current = outer;
}

// A dynamic loop's start (it closes the previous loop) and its next chunk (which ends the one before), around the
// runtime's own calls.
template <class F, class... A>
bool loop_start(F next, A... args) {
  if (wall_only()) return next(args...);
  close_loop();
  const bool r = next(args...);
  chunk_start = r ? now() : -1;
  return r;
}

template <class F, class... A>
bool loop_next(F next, A... args) {
  if (wall_only()) return next(args...);
  if (chunk_start >= 0 && num_chunks < kMaxChunks) chunk[num_chunks++] = now() - chunk_start;
  const bool r = next(args...);
  chunk_start = r ? now() : -1;
  return r;
}

}  // namespace

extern "C" {

void GOMP_parallel(void (*fn)(void*), void* data, unsigned threads, unsigned flags) {
  static auto next = real<void (*)(void (*)(void*), void*, unsigned, unsigned)>("GOMP_parallel");
  if (plan_threads() > 0) threads = 1;  // run on one thread what was cut for plan_threads()
  region(fn, [&] { next(fn, data, threads, flags); });
}

// `parallel for schedule(dynamic)` as one construct: the region and its loop (its chunks come from the _next calls).
void GOMP_parallel_loop_nonmonotonic_dynamic(void (*fn)(void*), void* data, unsigned threads, long start, long end,
                                             long incr, long chunk, unsigned flags) {
  static auto next = real<void (*)(void (*)(void*), void*, unsigned, long, long, long, long, unsigned)>(
      "GOMP_parallel_loop_nonmonotonic_dynamic");
  if (plan_threads() > 0) threads = 1;
  region(fn, [&] { next(fn, data, threads, start, end, incr, chunk, flags); });
}

bool GOMP_loop_nonmonotonic_dynamic_start(long s, long e, long inc, long ch, long* is, long* ie) {
  static auto next = real<bool (*)(long, long, long, long, long*, long*)>("GOMP_loop_nonmonotonic_dynamic_start");
  return loop_start(next, s, e, inc, ch, is, ie);
}

bool GOMP_loop_nonmonotonic_dynamic_next(long* is, long* ie) {
  static auto next = real<bool (*)(long*, long*)>("GOMP_loop_nonmonotonic_dynamic_next");
  return loop_next(next, is, ie);
}

using ull = unsigned long long;
bool GOMP_loop_ull_nonmonotonic_dynamic_start(bool up, ull s, ull e, ull inc, ull ch, ull* is, ull* ie) {
  static auto next = real<bool (*)(bool, ull, ull, ull, ull, ull*, ull*)>("GOMP_loop_ull_nonmonotonic_dynamic_start");
  return loop_start(next, up, s, e, inc, ch, is, ie);
}

bool GOMP_loop_ull_nonmonotonic_dynamic_next(ull* is, ull* ie) {
  static auto next = real<bool (*)(ull*, ull*)>("GOMP_loop_ull_nonmonotonic_dynamic_next");
  return loop_next(next, is, ie);
}

bool GOMP_single_start() {
  static auto next = real<bool (*)()>("GOMP_single_start");
  const bool r = next();
  if (r && !wall_only()) single_start = now();
  return r;
}

void GOMP_barrier() {
  static auto next = real<void (*)()>("GOMP_barrier");
  if (!wall_only()) {
    if (single_start >= 0 && current >= 0) regions[current].single += now() - single_start;
    single_start = -1;
  }
  next();
}

int omp_get_max_threads() {
  static auto next = real<int (*)()>("omp_get_max_threads");
  if (wall_only()) return next();  // called from any thread: no planning, no shared state
  static unsigned long lo[16], hi[16];
  static int ranges = -1;
  if (ranges < 0) {
    ranges = 0;
    const char* r = getenv("HGS_PLAN_RANGES");
    while (r && *r && ranges < 16) {
      char* end;
      lo[ranges] = strtoul(r, &end, 16);
      if (*end != '-') break;
      hi[ranges] = strtoul(end + 1, &end, 16);
      ++ranges;
      r = *end ? end + 1 : end;
    }
  }
  if (plan_threads() > 0) {
    void* ra = __builtin_return_address(0);
    Dl_info di;
    if (dladdr(ra, &di)) {
      const unsigned long off = static_cast<char*>(ra) - static_cast<char*>(di.dli_fbase);
      for (int i = 0; i < ranges; ++i)
        if (off >= lo[i] && off < hi[i]) return plan_threads();
    }
  }
  return next();
}

// Forgets everything recorded so far (bench_scale calls it, when present, after its warm-up step), so that the
// tables hold the timed steps alone.
void hgs_regions_reset() {
  for (int i = 0; i < num_regions; ++i) {
    const void* fn = regions[i].fn;
    regions[i] = Region{};
    regions[i].fn = const_cast<void*>(fn);
  }
  last_region = -1;
  num_chunks = 0;
}

}  // extern "C"

namespace {

struct Dump {
  ~Dump() {
    const char* out = getenv("HGS_REGIONS_OUT");
    if (!out) return;
    char path[4096];
    snprintf(path, sizeof path, "%s.%d", out, int(getpid()));
    FILE* f = fopen(path, "w");
    if (!f) return;
    for (int i = 0; i < num_regions; ++i) {
      const Region& r = regions[i];
      Dl_info di{};
      const bool ok = dladdr(r.fn, &di) != 0;
      const unsigned long off = ok ? static_cast<char*>(r.fn) - static_cast<char*>(di.dli_fbase) : 0;
      fprintf(f, "%lx %ld %.9f %.9f %.9f %ld", off, r.calls, r.seconds, r.single, r.dynamic, r.chunks);
      for (double m : r.makespan) fprintf(f, " %.9f", m);
      fprintf(f, " %.9f", r.after);
      fprintf(f, " %s\n", ok && di.dli_sname ? di.dli_sname : "?");
    }
    fclose(f);
  }
} dump;

}  // namespace
