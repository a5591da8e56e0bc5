// Included by each rasterizer kernel file after all its other includes (with raster_isa_end.h at its end): in the
// AVX-512 compilation (HGS_RASTER_AVX512, CMakeLists.txt) every function defined between the two is compiled
// with AVX-512 (F, VL, BW, DQ, CD) on top of the build's baseline, and nothing else is. The file is not compiled
// with -march=x86-64-v4 as a whole on purpose: the out-of-line copies of the inline functions and templates of
// the headers it uses (std::vector, the workspace's scratch, ...) are shared by name with the portable
// compilation, and the linker keeps one of them for the whole program; compiled with AVX-512 they would crash
// the portable path on a CPU without it (tests/render/isa_objects_test.sh checks the objects). Header code stays
// baseline and is inlined into the kernels (a function may inline a callee whose instruction sets are a subset
// of its own). GCC only: clang (the fuzzing build) rejects the 64-byte double packs crossing from baseline
// helpers into AVX-512 functions, so there the avx512 namespace holds baseline code (correct, not faster).
// No include guard: it opens a region.
#if defined(HGS_RASTER_AVX512) && defined(__GNUC__) && !defined(__clang__)
#pragma GCC push_options
#pragma GCC target("avx512f,avx512vl,avx512bw,avx512dq,avx512cd")
#endif
