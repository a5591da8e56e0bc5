// bfloat16 products on oneDNN: see gemm_bf16.h. One matmul primitive per (shape, strides, options, threads),
// created on first use and kept (creating one costs ~0.1-1 ms: kernel generation); memory objects wrap the
// callers' pointers, nothing is copied except the rounding of operands by to_bf16.
#include "nn/gemm_bf16.h"

#include <omp.h>
#include <oneapi/dnnl/dnnl.hpp>

#include <map>
#include <mutex>
#include <tuple>
#include <unordered_map>
#include <vector>

#include "core/error.h"
#include "core/half.h"
#include "nn/fastmath.h"
#include "nn/thread_pool.h"

namespace hgs::nn {

Precision parse_precision(const std::string& s, const char* what) {
  if (s == "f32" || s == "fp32" || s == "float32") return Precision::F32;
  if (s == "bf16" || s == "bfloat16") return Precision::BF16;
  fail("{}: unknown precision \"{}\" (f32 or bf16)", what, s);
}

const char* precision_name(Precision p) { return p == Precision::BF16 ? "bf16" : "f32"; }

namespace {

HGS_AVX512_CLONE void convert_rows(const float* x, long r0, long r1, int cols, int ld, uint16_t* out, float scale) {
  for (long i = r0; i < r1; ++i) {
    const float* s = x + size_t(i) * ld;
    uint16_t* o = out + size_t(i) * cols;
    if (scale == 1.f) {
#pragma omp simd
      for (int j = 0; j < cols; ++j) o[j] = float_to_bf16(s[j]);
    } else {
#pragma omp simd
      for (int j = 0; j < cols; ++j) o[j] = float_to_bf16(scale * s[j]);
    }
  }
}

HGS_AVX512_CLONE void sum_rows(const float* a, const float* b, size_t n, uint16_t* out) {
#pragma omp simd
  for (size_t i = 0; i < n; ++i) out[i] = float_to_bf16(a[i] + b[i]);
}

dnnl::engine& engine() {
  static dnnl::engine e(dnnl::engine::kind::cpu, 0);
  return e;
}

using Key = std::tuple<int, int, int, int, int, int, bool, float, bool, float, int>;

dnnl::matmul::primitive_desc make_pd(int m, int n, int k, int lda, int ldb, bool trans_b, float alpha, bool bias,
                                     float beta, int ldc) {
  using dt = dnnl::memory::data_type;
  using dims = dnnl::memory::dims;
  const dnnl::memory::desc a({m, k}, dt::bf16, dims{lda, 1});
  const dnnl::memory::desc b({k, n}, dt::bf16, trans_b ? dims{1, ldb} : dims{ldb, 1});
  const dnnl::memory::desc c({m, n}, dt::f32, dims{ldc, 1});
  const dnnl::memory::desc bd({1, n}, dt::f32, dims{n, 1});
  dnnl::primitive_attr attr;
  // The caller's scratchpad (per calling thread, see gemm_bf16): with the library's own, two threads running
  // the same cached primitive at once (the decoder's one prompt per thread) sometimes got wrong products.
  attr.set_scratchpad_mode(dnnl::scratchpad_mode::user);
  if (alpha != 1.f) attr.set_output_scales(0, {alpha});
  if (beta != 0.f) {
    dnnl::post_ops po;
    po.append_sum(beta);
    attr.set_post_ops(po);
  }
  const dnnl::matmul::desc d = bias ? dnnl::matmul::desc(a, b, bd, c) : dnnl::matmul::desc(a, b, c);
  return dnnl::matmul::primitive_desc(d, attr, engine());
}

struct Cached {
  dnnl::matmul mm;
  size_t scratch = 0;  // bytes of scratchpad it needs
};

const Cached& primitive(const Key& key) {
  static std::mutex mu;
  static std::map<Key, Cached> cache;
  std::lock_guard<std::mutex> lock(mu);
  auto it = cache.find(key);
  if (it != cache.end()) return it->second;
  const auto [m, n, k, lda, ldb, ldc, trans_b, alpha, bias, beta, threads] = key;
  (void)threads;  // part of the key: oneDNN fixes a primitive's thread split when it creates it
  try {
    const dnnl::matmul::primitive_desc pd = make_pd(m, n, k, lda, ldb, trans_b, alpha, bias, beta, ldc);
    return cache.emplace(key, Cached{dnnl::matmul(pd), pd.scratchpad_desc().get_size()}).first->second;
  } catch (const dnnl::error& e) {
    fail("bf16 matrix product [{} x {}] x [{} x {}]: not available on this CPU (oneDNN: {}); use --precision f32", m, k,
         k, n, e.what());
  }
}

}  // namespace

void to_bf16(const float* x, int rows, int cols, int ld, uint16_t* out, float scale) {
  parallel_for(rows, std::max(1, 65536 / std::max(cols, 1)),
               [&](long r0, long r1) { convert_rows(x, r0, r1, cols, ld, out, scale); });
}

void split_heads_bf16(const float* x, int n, int ld, int heads, int hd, uint16_t* out) {
  parallel_for(heads, 2, [&](long h0, long h1) {
    for (long h = h0; h < h1; ++h) convert_rows(x + h * hd, 0, n, hd, ld, out + size_t(h) * n * hd, 1.f);
  });
}

void convert_to_bf16_serial(const float* x, int rows, int cols, int ld, uint16_t* out, float scale) {
  convert_rows(x, 0, rows, cols, ld, out, scale);
}

void sum_to_bf16_serial(const float* a, const float* b, size_t n, uint16_t* out) { sum_rows(a, b, n, out); }

const uint16_t* rounded_or_convert(const uint16_t* given, const float* x, int rows, int cols,
                                   std::vector<uint16_t>& buf) {
  if (given) return given;
  buf.resize(size_t(rows) * cols);
  convert_rows(x, 0, rows, cols, cols, buf.data(), 1.f);
  return buf.data();
}

std::vector<uint16_t> to_bf16(const std::vector<float>& x) {
  std::vector<uint16_t> out(x.size());
  convert_rows(x.data(), 0, 1, int(x.size()), 0, out.data(), 1.f);
  return out;
}

void gemm_bf16(int m, int n, int k, const uint16_t* a, int lda, const uint16_t* b, int ldb, bool trans_b, float alpha,
               const float* bias, float beta, float* c, int ldc) {
  if (m <= 0 || n <= 0) return;
  if (beta != 0.f && beta != 1.f) fail("gemm_bf16: beta must be 0 or 1, not {}", beta);
  if (k <= 0) {  // empty sum: c = bias + beta * c
    for (int i = 0; i < m; ++i)
      for (int j = 0; j < n; ++j) {
        float& o = c[size_t(i) * ldc + j];
        o = (beta != 0.f ? o : 0.f) + (bias ? bias[j] : 0.f);
      }
    return;
  }
  // oneDNN scales the bias with the output scale (alpha (a b + bias)): with alpha != 1 the bias is added here.
  const float* late_bias = alpha != 1.f ? bias : nullptr;
  if (late_bias) bias = nullptr;
  const Key key{m, n, k, lda, ldb, ldc, trans_b, alpha, bias != nullptr, beta, omp_get_max_threads()};
  const Cached& prim = primitive(key);
  using dt = dnnl::memory::data_type;
  using dims = dnnl::memory::dims;
  dnnl::engine& eng = engine();
  const dnnl::memory A({{m, k}, dt::bf16, dims{lda, 1}}, eng, const_cast<uint16_t*>(a));
  const dnnl::memory B({{k, n}, dt::bf16, trans_b ? dims{1, ldb} : dims{ldb, 1}}, eng, const_cast<uint16_t*>(b));
  const dnnl::memory C({{m, n}, dt::f32, dims{ldc, 1}}, eng, c);
  std::unordered_map<int, dnnl::memory> args{{DNNL_ARG_SRC, A}, {DNNL_ARG_WEIGHTS, B}, {DNNL_ARG_DST, C}};
  if (bias) args.emplace(DNNL_ARG_BIAS, dnnl::memory({{1, n}, dt::f32, dims{n, 1}}, eng, const_cast<float*>(bias)));
  thread_local std::vector<uint8_t> scratch;
  if (prim.scratch > 0) {
    if (scratch.size() < prim.scratch + 64) scratch.resize(prim.scratch + 64);
    void* p = scratch.data() + (64 - reinterpret_cast<uintptr_t>(scratch.data()) % 64) % 64;  // 64-byte aligned
    args.emplace(DNNL_ARG_SCRATCHPAD, dnnl::memory({{dnnl::memory::dim(prim.scratch)}, dt::u8, dims{1}}, eng, p));
  }
  dnnl::stream s(eng);
  prim.mm.execute(s, args);
  s.wait();
  if (late_bias)
    for (int i = 0; i < m; ++i)
      for (int j = 0; j < n; ++j) c[size_t(i) * ldc + j] += late_bias[j];
}

std::string bf16_kernel_name() {
  try {
    return make_pd(64, 64, 64, 64, 64, true, 1.f, false, 0.f, 64).impl_info_str();
  } catch (const dnnl::error&) {
    return "none";
  }
}

}  // namespace hgs::nn
