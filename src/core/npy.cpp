#include "core/npy.h"

#include <cstring>
#include <fstream>
#include <regex>

#include "core/error.h"
#include "core/fs.h"
#include "core/half.h"

namespace hgs {

size_t dtype_size(DType t) {
  switch (t) {
    case DType::F16: return 2;
    case DType::F32: return 4;
    case DType::U8: return 1;
    case DType::U16: return 2;
    case DType::I32: return 4;
  }
  return 0;
}

const char* dtype_descr(DType t) {
  switch (t) {
    case DType::F16: return "<f2";
    case DType::F32: return "<f4";
    case DType::U8: return "|u1";
    case DType::U16: return "<u2";
    case DType::I32: return "<i4";
  }
  return "";
}

size_t NpyArray::size() const {
  size_t n = 1;
  for (size_t s : shape) n *= s;
  return n;
}

std::vector<float> NpyArray::to_float() const {
  size_t n = size();
  std::vector<float> out(n);
  switch (dtype) {
    case DType::F16:
      for (size_t i = 0; i < n; ++i) out[i] = half_to_float(as<uint16_t>()[i]);
      break;
    case DType::F32:
      if (n) std::memcpy(out.data(), data.data(), n * 4);
      break;  // empty: both may be null
    case DType::U8:
      for (size_t i = 0; i < n; ++i) out[i] = as<uint8_t>()[i];
      break;
    case DType::U16:
      for (size_t i = 0; i < n; ++i) out[i] = as<uint16_t>()[i];
      break;
    case DType::I32:
      for (size_t i = 0; i < n; ++i) out[i] = static_cast<float>(as<int32_t>()[i]);
      break;
  }
  return out;
}

std::vector<size_t> parse_npy_shape(const std::string& s, size_t element_bytes, const std::string& name) {
  // reject anything in the shape tuple other than digits, commas and spaces
  for (char c : s)
    if (!(std::isdigit(static_cast<unsigned char>(c)) || c == ',' || c == ' '))
      fail("{}: malformed NPY shape '({})'", name, s.substr(0, 80));
  // Dimensions and the body size in bytes must fit a size_t (checked here, before anything is allocated).
  std::vector<size_t> shape;
  std::regex num(R"(\s*(\d+)\s*,?)");
  size_t bytes = element_bytes;
  for (std::sregex_iterator it(s.begin(), s.end(), num), end; it != end; ++it) {
    const std::string d = (*it)[1];
    size_t v = 0;
    for (char c : d)
      if (__builtin_mul_overflow(v, size_t(10), &v) || __builtin_add_overflow(v, size_t(c - '0'), &v))
        fail("{}: NPY dimension {} is too large", name, d.substr(0, 40));
    if (__builtin_mul_overflow(bytes, v, &bytes)) fail("{}: NPY shape ({}) is too large", name, s.substr(0, 80));
    shape.push_back(v);
  }
  return shape;
}

namespace {

struct Header {
  DType dtype;
  std::vector<size_t> shape;
  size_t body_offset;
};

Header parse_header(const uint8_t* b, size_t size, const std::string& name) {
  static const uint8_t magic[6] = {0x93, 'N', 'U', 'M', 'P', 'Y'};
  if (size < 10 || std::memcmp(b, magic, 6) != 0) fail("{}: not an NPY file (bad magic)", name);
  uint8_t major = b[6];
  size_t hlen, hstart;
  if (major == 1) {
    hlen = b[8] | (b[9] << 8);
    hstart = 10;
  } else if (major == 2 || major == 3) {
    if (size < 12) fail("{}: truncated NPY header", name);
    hlen = b[8] | (b[9] << 8) | (b[10] << 16) | (static_cast<size_t>(b[11]) << 24);
    hstart = 12;
  } else {
    fail("{}: unsupported NPY version {}", name, major);
  }
  if (hlen > kMaxNpyHeader) fail("{}: NPY header of {} bytes is too long (at most {})", name, hlen, kMaxNpyHeader);
  if (hstart + hlen > size) fail("{}: truncated NPY header", name);
  std::string h(reinterpret_cast<const char*>(b + hstart), hlen);
  std::smatch m;
  if (!std::regex_search(h, m, std::regex(R"('descr'\s*:\s*'([^']*)')"))) fail("{}: NPY header has no 'descr'", name);
  std::string d = m[1];
  DType t;
  if (d == "<f2") t = DType::F16;
  else if (d == "<f4") t = DType::F32;
  else if (d == "|u1" || d == "<u1") t = DType::U8;
  else if (d == "<u2") t = DType::U16;
  else if (d == "<i4") t = DType::I32;
  else fail("{}: unsupported NPY dtype '{}' (want float16, float32, uint8, uint16 or int32, little endian)", name, d);
  if (!std::regex_search(h, m, std::regex(R"('fortran_order'\s*:\s*(True|False))")))
    fail("{}: NPY header has no 'fortran_order'", name);
  if (m[1] == "True") fail("{}: Fortran-order NPY arrays are not supported (save with C order)", name);
  if (!std::regex_search(h, m, std::regex(R"('shape'\s*:\s*\(([^)]*)\))"))) fail("{}: NPY header has no 'shape'", name);
  std::vector<size_t> shape = parse_npy_shape(m[1], dtype_size(t), name);
  return {t, shape, hstart + hlen};
}

}  // namespace

NpyArray parse_npy(const uint8_t* b, size_t size, const std::string& name) {
  Header h = parse_header(b, size, name);
  NpyArray a;
  a.dtype = h.dtype;
  a.shape = h.shape;
  size_t need = a.size() * dtype_size(a.dtype);
  if (need > size - h.body_offset)
    fail("{}: truncated NPY body ({} bytes, header says {})", name, size - h.body_offset, need);
  a.data.assign(b + h.body_offset, b + h.body_offset + need);
  return a;
}

NpyArray read_npy(const std::filesystem::path& path) {
  auto bytes = read_file_bytes(path);
  return parse_npy(bytes.data(), bytes.size(), path.string());
}

NpyArray read_npy_header(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) fail("{}: file not found", path.string());
  std::vector<uint8_t> buf(4096);
  in.read(reinterpret_cast<char*>(buf.data()), buf.size());
  buf.resize(static_cast<size_t>(in.gcount()));
  Header h = parse_header(buf.data(), buf.size(), path.string());
  NpyArray a;
  a.dtype = h.dtype;
  a.shape = h.shape;
  return a;
}

std::vector<uint8_t> encode_npy(const NpyArray& a) {
  std::string shape = "(";
  for (size_t i = 0; i < a.shape.size(); ++i)
    shape += std::to_string(a.shape[i]) + (a.shape.size() == 1 ? "," : (i + 1 < a.shape.size() ? ", " : ""));
  shape += ")";
  std::string h = fmt::format("{{'descr': '{}', 'fortran_order': False, 'shape': {}, }}", dtype_descr(a.dtype), shape);
  size_t total = 10 + h.size() + 1;
  size_t pad = (64 - total % 64) % 64;
  h += std::string(pad, ' ') + "\n";
  std::vector<uint8_t> out = {
      0x93, 'N', 'U', 'M', 'P', 'Y', 1, 0, static_cast<uint8_t>(h.size() & 0xff), static_cast<uint8_t>(h.size() >> 8)};
  // GCC 12 false positive: -Warray-bounds / -Wstringop-overread take the vector's first 10 bytes for the whole
  // buffer of the insert.
#ifndef __clang__  // warnings clang does not have
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Warray-bounds"
#pragma GCC diagnostic ignored "-Wstringop-overread"
#endif
  out.insert(out.end(), h.begin(), h.end());
#ifndef __clang__
#pragma GCC diagnostic pop
#endif
  out.insert(out.end(), a.data.begin(), a.data.end());
  return out;
}

void write_npy(const std::filesystem::path& path, const NpyArray& a) {
  if (a.data.size() != a.size() * dtype_size(a.dtype))
    fail("{}: internal error: NPY data size mismatch", path.string());
  auto bytes = encode_npy(a);
  atomic_write_bytes(path, bytes.data(), bytes.size());
}

NpyArray make_npy_f32(const std::vector<size_t>& shape, const float* data) {
  NpyArray a;
  a.dtype = DType::F32;
  a.shape = shape;
  a.data.resize(a.size() * 4);
  std::memcpy(a.data.data(), data, a.data.size());
  return a;
}

NpyArray make_npy_f16(const std::vector<size_t>& shape, const float* data) {
  NpyArray a;
  a.dtype = DType::F16;
  a.shape = shape;
  a.data.resize(a.size() * 2);
  uint16_t* d = a.as<uint16_t>();
  for (size_t i = 0; i < a.size(); ++i) d[i] = float_to_half(data[i]);
  return a;
}

}  // namespace hgs
