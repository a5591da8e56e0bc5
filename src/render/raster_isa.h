// Which compilation of the rasterizer kernels runs. rasterize_forward.cpp / rasterize_backward.cpp are compiled
// twice (CMakeLists.txt): with the build's baseline flags (namespace avx2: the portable x86-64-v3 build) and with
// AVX-512 enabled for the kernels (namespace avx512, raster_isa_begin.h: the same 8-pixel batches and the same
// arithmetic, with 32 vector registers, so the walks' accumulators stay in registers, and mask registers for the
// lane selects).
// rasterize_forward / rasterize_backward (rasterize.h) run the one chosen here: avx512 on CPUs with AVX-512 (F,
// BW, CD, DQ, VL), else avx2. HGS_RASTER_ISA=avx2|avx512 in the environment (read once) or set_raster_isa()
// overrides the choice. Both compile the same source with the same compiler, which fuses the same a * b + c into
// FMA in both (GCC contracts by default in C++; both instruction sets have FMA), so their results are bitwise
// equal; not a language guarantee, so test_isa.cpp checks it on every build.
// Both process 8-pixel batches: 16-pixel batches (one AVX-512 register) make the whole step no faster
// (docs/performance.md, "The RGB step").
#pragma once
#include <string>

#include "render/rasterize.h"

namespace hgs::render {

enum class RasterIsa { kAvx2, kAvx512 };

bool raster_isa_supported(RasterIsa isa);  // by this CPU
RasterIsa raster_isa();                    // the one rasterize_forward uses on this CPU
void set_raster_isa(RasterIsa isa);        // fails when the CPU does not support it
// The channel path (rasterize.h) of every call whose inputs leave it to ChannelPath::kAuto; kAuto restores the
// kernels' own choice. HGS_RASTER_CHANNELS=lists|folded in the environment sets it at start-up.
void set_raster_channel_path(ChannelPath path);
const char* raster_isa_name(RasterIsa isa);           // "avx2" / "avx512"
RasterIsa parse_raster_isa(const std::string& name);  // "avx2" / "avx512"; fails otherwise
// The choice for a value of HGS_RASTER_ISA (null or empty: the best the CPU supports); fails with a message
// naming the variable when the value is unknown or the CPU lacks it.
RasterIsa raster_isa_from_env(const char* value);

// The two compilations (called through rasterize_forward / rasterize_backward / rasterize_depth_at).
namespace avx2 {
template <class T>
void rasterize_forward(const RasterInputs<T>& in, const Binning& bins, RasterWorkspace<T>& ws,
                       const RasterOutputs<T>& out);
template <class T>
void rasterize_backward(const RasterInputs<T>& in, const Binning& bins, RasterWorkspace<T>& ws, const T* final_T,
                        const int32_t* last, const RasterGrads<T>& g);
template <class T>
void rasterize_depth_at(const RasterInputs<T>& in, const Binning& bins, RasterWorkspace<T>& ws, const TilePixels& px,
                        T* alpha, T* depth);
}  // namespace avx2
namespace avx512 {
template <class T>
void rasterize_forward(const RasterInputs<T>& in, const Binning& bins, RasterWorkspace<T>& ws,
                       const RasterOutputs<T>& out);
template <class T>
void rasterize_backward(const RasterInputs<T>& in, const Binning& bins, RasterWorkspace<T>& ws, const T* final_T,
                        const int32_t* last, const RasterGrads<T>& g);
template <class T>
void rasterize_depth_at(const RasterInputs<T>& in, const Binning& bins, RasterWorkspace<T>& ws, const TilePixels& px,
                        T* alpha, T* depth);
}  // namespace avx512

}  // namespace hgs::render
