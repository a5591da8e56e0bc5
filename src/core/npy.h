// NPY (NumPy .npy, format versions 1.0-3.0) reader and writer. Supported dtypes: float16, float32, uint8,
// uint16, int32, little endian, C order. Anything else (Fortran order, big endian, other dtypes, a truncated
// body) is rejected with a one-line error naming the file.
#pragma once
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace hgs {

enum class DType { F16, F32, U8, U16, I32 };

size_t dtype_size(DType t);
const char* dtype_descr(DType t);  // "<f2", "<f4", "|u1", "<u2", "<i4"

struct NpyArray {
  DType dtype = DType::F32;
  std::vector<size_t> shape;
  std::vector<uint8_t> data;  // raw little-endian elements, C order

  size_t size() const;  // number of elements
  template <typename T>
  const T* as() const {
    return reinterpret_cast<const T*>(data.data());
  }
  template <typename T>
  T* as() {
    return reinterpret_cast<T*>(data.data());
  }
  std::vector<float> to_float() const;  // any dtype, converted element by element
};

// Headers above this many bytes are refused (numpy itself writes at most 10000 by default).
constexpr size_t kMaxNpyHeader = 65536;
// The dimensions of the inside of an NPY 'shape' tuple ("3, 4" or "7,"): digits, commas and spaces only; each
// dimension and the body size (element_bytes times their product) must fit a size_t. Errors name `name`.
std::vector<size_t> parse_npy_shape(const std::string& tuple, size_t element_bytes, const std::string& name);

NpyArray read_npy(const std::filesystem::path& path);
// Parses an in-memory .npy file; `name` is used in error messages.
NpyArray parse_npy(const uint8_t* bytes, size_t size, const std::string& name);
// Reads only the header (dtype and shape) without loading the body.
NpyArray read_npy_header(const std::filesystem::path& path);

std::vector<uint8_t> encode_npy(const NpyArray& a);
void write_npy(const std::filesystem::path& path, const NpyArray& a);  // atomic
NpyArray make_npy_f32(const std::vector<size_t>& shape, const float* data);
NpyArray make_npy_f16(const std::vector<size_t>& shape, const float* data);  // converts to half

}  // namespace hgs
