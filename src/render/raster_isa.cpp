// Run-time choice between the AVX2 and AVX-512 compilations of the rasterizer kernels (raster_isa.h), and the
// public rasterize_forward / rasterize_backward / rasterize_depth_at that dispatch to them.
#include "render/raster_isa.h"

#include <atomic>
#include <cstdlib>
#include <string>

#include "core/error.h"

namespace hgs::render {
namespace {

std::atomic<int>& current() {
  static std::atomic<int> c{int(raster_isa_from_env(std::getenv("HGS_RASTER_ISA")))};
  return c;
}

// The channel path of every call that leaves it to kAuto: HGS_RASTER_CHANNELS=lists|folded (read once) or
// set_raster_channel_path().
std::atomic<int>& channel_override_state() {
  static std::atomic<int> p{[] {
    const char* v = std::getenv("HGS_RASTER_CHANNELS");
    if (!v || !*v) return int(ChannelPath::kAuto);
    const std::string s = v;
    if (s == "lists") return int(ChannelPath::kVisitLists);
    if (s == "folded") return int(ChannelPath::kFolded);
    fail("HGS_RASTER_CHANNELS={}: unknown channel path (lists or folded)", s);
  }()};
  return p;
}
ChannelPath channel_override() { return ChannelPath(channel_override_state().load(std::memory_order_relaxed)); }

}  // namespace

bool raster_isa_supported(RasterIsa isa) {
  if (isa == RasterIsa::kAvx2) return true;  // the build's baseline
  __builtin_cpu_init();
  return __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512bw") &&
         __builtin_cpu_supports("avx512cd") && __builtin_cpu_supports("avx512dq") && __builtin_cpu_supports("avx512vl");
}

RasterIsa raster_isa() { return RasterIsa(current().load(std::memory_order_relaxed)); }

void set_raster_isa(RasterIsa isa) {
  if (!raster_isa_supported(isa)) fail("rasterizer: this CPU does not support {}", raster_isa_name(isa));
  current().store(int(isa), std::memory_order_relaxed);
}

void set_raster_channel_path(ChannelPath path) { channel_override_state().store(int(path), std::memory_order_relaxed); }

const char* raster_isa_name(RasterIsa isa) { return isa == RasterIsa::kAvx512 ? "avx512" : "avx2"; }

RasterIsa raster_isa_from_env(const char* value) {
  if (!value || !*value) return raster_isa_supported(RasterIsa::kAvx512) ? RasterIsa::kAvx512 : RasterIsa::kAvx2;
  const std::string v = value;
  if (v != "avx2" && v != "avx512") fail("HGS_RASTER_ISA={}: unknown rasterizer ISA (avx2 or avx512)", v);
  const RasterIsa isa = parse_raster_isa(v);
  if (!raster_isa_supported(isa)) fail("HGS_RASTER_ISA={}: this CPU does not support it", v);
  return isa;
}

RasterIsa parse_raster_isa(const std::string& name) {
  if (name == "avx2") return RasterIsa::kAvx2;
  if (name == "avx512") return RasterIsa::kAvx512;
  fail("unknown rasterizer ISA '{}' (avx2 or avx512)", name);
}

template <class T>
void rasterize_forward(const RasterInputs<T>& in, const Binning& bins, RasterWorkspace<T>& ws,
                       const RasterOutputs<T>& out) {
  if (in.channel_path == ChannelPath::kAuto && channel_override() != ChannelPath::kAuto) {
    RasterInputs<T> forced = in;
    forced.channel_path = channel_override();
    return rasterize_forward(forced, bins, ws, out);
  }
  if (raster_isa() == RasterIsa::kAvx512) avx512::rasterize_forward(in, bins, ws, out);
  else avx2::rasterize_forward(in, bins, ws, out);
}

template <class T>
void rasterize_backward(const RasterInputs<T>& in, const Binning& bins, RasterWorkspace<T>& ws, const T* final_T,
                        const int32_t* last, const RasterGrads<T>& g) {
  if (in.channel_path == ChannelPath::kAuto && channel_override() != ChannelPath::kAuto) {
    RasterInputs<T> forced = in;
    forced.channel_path = channel_override();
    return rasterize_backward(forced, bins, ws, final_T, last, g);
  }
  // Both compilations lay out the workspace alike, so either may differentiate the other's forward.
  if (raster_isa() == RasterIsa::kAvx512) avx512::rasterize_backward(in, bins, ws, final_T, last, g);
  else avx2::rasterize_backward(in, bins, ws, final_T, last, g);
}

template <class T>
void rasterize_depth_at(const RasterInputs<T>& in, const Binning& bins, RasterWorkspace<T>& ws, const TilePixels& px,
                        T* alpha, T* depth) {
  if (raster_isa() == RasterIsa::kAvx512) avx512::rasterize_depth_at(in, bins, ws, px, alpha, depth);
  else avx2::rasterize_depth_at(in, bins, ws, px, alpha, depth);
}

template void rasterize_forward<float>(const RasterInputs<float>&, const Binning&, RasterWorkspace<float>&,
                                       const RasterOutputs<float>&);
template void rasterize_forward<double>(const RasterInputs<double>&, const Binning&, RasterWorkspace<double>&,
                                        const RasterOutputs<double>&);
template void rasterize_backward<float>(const RasterInputs<float>&, const Binning&, RasterWorkspace<float>&,
                                        const float*, const int32_t*, const RasterGrads<float>&);
template void rasterize_backward<double>(const RasterInputs<double>&, const Binning&, RasterWorkspace<double>&,
                                         const double*, const int32_t*, const RasterGrads<double>&);

template void rasterize_depth_at<float>(const RasterInputs<float>&, const Binning&, RasterWorkspace<float>&,
                                        const TilePixels&, float*, float*);
template void rasterize_depth_at<double>(const RasterInputs<double>&, const Binning&, RasterWorkspace<double>&,
                                         const TilePixels&, double*, double*);

}  // namespace hgs::render
