// bfloat16 matrix products for the CLIP and SAM forwards: an approximation of their float32 sgemm path, chosen
// per model (Precision::BF16). Operands are rounded to bfloat16 (8 significant bits, round to nearest even),
// products are accumulated in float32 and written as float32 (the layout of every caller stays float32). The
// products run on oneDNN (Debian libdnnl), which uses the CPU's AMX tiles or AVX512-BF16 instructions when
// present (4-5x the float32 sgemm rate measured on a Sapphire Rapids core) and a slower emulation otherwise.
// Written on oneDNN rather than by hand: AMX tile kernels with their packing are what oneDNN already does well.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

namespace hgs::nn {

enum class Precision { F32, BF16 };

// "f32" or "bf16"; anything else is an hgs::Error naming `what` (e.g. "--precision").
Precision parse_precision(const std::string& s, const char* what);
const char* precision_name(Precision p);

// out [rows, cols] (contiguous) = bf16(scale * x [rows, cols] with row stride ld), round to nearest even.
void to_bf16(const float* x, int rows, int cols, int ld, uint16_t* out, float scale = 1.f);
std::vector<uint16_t> to_bf16(const std::vector<float>& x);
// out [heads, n, hd] = bf16(x [n, heads * hd] with row stride ld): the columns of each head made contiguous.
void split_heads_bf16(const float* x, int n, int ld, int heads, int hd, uint16_t* out);
// The same on the calling thread only (for callers that already run one unit of work per thread).
void convert_to_bf16_serial(const float* x, int rows, int cols, int ld, uint16_t* out, float scale = 1.f);
// `given` when the caller already has x [rows, cols] (contiguous) rounded, else x rounded into buf on the calling
// thread: buf.data().
const uint16_t* rounded_or_convert(const uint16_t* given, const float* x, int rows, int cols,
                                   std::vector<uint16_t>& buf);
// out [n] = bf16(a [n] + b [n]) on the calling thread (a sum rounded once, without a float32 copy).
void sum_to_bf16_serial(const float* a, const float* b, size_t n, uint16_t* out);

// c [m, n] = alpha * a [m, k] op(b) + bias [n] + beta * c, with a [m, k] (row stride lda) and b bfloat16:
// op(b) = b^T for b [n, k] (row stride ldb) when trans_b, else b [k, n] (row stride ldb). beta is 0 or 1,
// bias may be null. Float32 accumulation. Runs on omp_get_max_threads() threads of the calling thread.
void gemm_bf16(int m, int n, int k, const uint16_t* a, int lda, const uint16_t* b, int ldb, bool trans_b, float alpha,
               const float* bias, float beta, float* c, int ldc);

// The oneDNN kernel that bfloat16 products use on this CPU (e.g. "brg:avx512_core_amx_bf16"), for reports.
std::string bf16_kernel_name();

}  // namespace hgs::nn
