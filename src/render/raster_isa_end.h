// Closes the region opened by raster_isa_begin.h.
// No include guard: it closes a region.
#if defined(HGS_RASTER_AVX512) && defined(__GNUC__) && !defined(__clang__)
#pragma GCC pop_options
#endif
