// safetensors reader and writer: see safetensors.h (mmap + nlohmann-json header, bounds checks per tensor).
#include "nn/safetensors.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstring>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/fs.h"
#include "core/half.h"

namespace hgs::nn {
namespace {

size_t dtype_bytes(StDType t) { return t == StDType::F32 ? 4 : 2; }

StDType parse_dtype(const std::string& s) {
  if (s == "F32") return StDType::F32;
  if (s == "F16") return StDType::F16;
  if (s == "BF16") return StDType::BF16;
  return StDType::Other;
}

}  // namespace

size_t TensorInfo::numel() const {
  size_t n = 1;
  for (auto d : shape) n *= size_t(d);
  return n;
}

std::string shape_str(const std::vector<int64_t>& shape) {
  std::string s = "[";
  for (size_t i = 0; i < shape.size(); ++i)
    s += (i ? ", " : "") + (shape[i] < 0 ? std::string("*") : std::to_string(shape[i]));
  return s + "]";
}

SafeTensors::SafeTensors(const std::filesystem::path& path) : path_(path) {
  const std::string p = path.string();
  int fd = ::open(p.c_str(), O_RDONLY);
  if (fd < 0) {
    if (!std::filesystem::exists(path)) fail("{}: file not found", p);
    fail("{}: cannot open for reading", p);
  }
  struct stat st {};
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd);
    fail("{}: not a regular file", p);
  }
  map_size_ = size_t(st.st_size);
  if (map_size_ < 8) {
    ::close(fd);
    fail("{}: not a safetensors file (only {} bytes; truncated?)", p, map_size_);
  }
  void* m = ::mmap(nullptr, map_size_, PROT_READ, MAP_PRIVATE, fd, 0);
  ::close(fd);
  if (m == MAP_FAILED) fail("{}: cannot memory-map the file", p);
  map_ = static_cast<const uint8_t*>(m);
  try {
    uint64_t hlen = 0;
    for (int i = 0; i < 8; ++i) hlen |= uint64_t(map_[i]) << (8 * i);
    if (hlen > map_size_ - 8)
      fail("{}: header length {} exceeds the file size {} (truncated or not a safetensors file)", p, hlen, map_size_);
    data_start_ = 8 + size_t(hlen);
    nlohmann::json h;
    try {
      h = nlohmann::json::parse(map_ + 8, map_ + data_start_);
    } catch (const nlohmann::json::exception& e) {
      fail("{}: the header is not valid JSON (not a safetensors file?)", p);
    }
    if (!h.is_object()) fail("{}: the header is not a JSON object", p);
    const size_t data_size = map_size_ - data_start_;
    for (auto& [name, v] : h.items()) {
      if (name == "__metadata__") {
        if (v.is_object())
          for (auto& [k, mv] : v.items())
            if (mv.is_string()) metadata_[k] = mv.get<std::string>();
        continue;
      }
      if (!v.is_object() || !v.contains("dtype") || !v.contains("shape") || !v.contains("data_offsets") ||
          !v["dtype"].is_string() || !v["shape"].is_array() || !v["data_offsets"].is_array() ||
          v["data_offsets"].size() != 2)
        fail("{}: tensor '{}' has a malformed header entry", p, name);
      TensorInfo t;
      t.name = name;
      t.dtype_name = v["dtype"].get<std::string>();
      t.dtype = parse_dtype(t.dtype_name);
      for (auto& d : v["shape"]) {
        if (!d.is_number_integer() || d.get<int64_t>() < 0) fail("{}: tensor '{}' has a bad shape", p, name);
        t.shape.push_back(d.get<int64_t>());
      }
      for (auto& o : v["data_offsets"])
        if (!o.is_number_unsigned()) fail("{}: tensor '{}' has bad data_offsets", p, name);
      t.begin = v["data_offsets"][0].get<size_t>();
      t.end = v["data_offsets"][1].get<size_t>();
      if (t.begin > t.end)
        fail("{}: tensor '{}' has data_offsets [{}, {}] in the wrong order", p, name, t.begin, t.end);
      if (t.end > data_size)
        fail("{}: tensor '{}' ends at byte {} of the data section but the file holds only {} bytes there (truncated?)",
             p, name, t.end, data_size);
      if (t.dtype != StDType::Other && t.end - t.begin != t.numel() * dtype_bytes(t.dtype))
        fail("{}: tensor '{}' ({} {}) should take {} bytes but its data_offsets span {}", p, name, t.dtype_name,
             shape_str(t.shape), t.numel() * dtype_bytes(t.dtype), t.end - t.begin);
      tensors_[name] = std::move(t);
    }
  } catch (...) {
    ::munmap(const_cast<uint8_t*>(map_), map_size_);
    map_ = nullptr;
    throw;
  }
}

SafeTensors::~SafeTensors() {
  if (map_) ::munmap(const_cast<uint8_t*>(map_), map_size_);
}

const TensorInfo& SafeTensors::info(const std::string& name) const {
  auto it = tensors_.find(name);
  if (it == tensors_.end()) fail("{}: missing tensor '{}'", path_.string(), name);
  return it->second;
}

std::vector<std::string> SafeTensors::names() const {
  std::vector<std::string> r;
  for (auto& [k, v] : tensors_) r.push_back(k);
  return r;
}

void SafeTensors::check_shape(const std::string& name, const std::vector<int64_t>& shape) const {
  const TensorInfo& t = info(name);
  bool ok = t.shape.size() == shape.size();
  for (size_t i = 0; ok && i < shape.size(); ++i) ok = shape[i] < 0 || shape[i] == t.shape[i];
  if (!ok)
    fail("{}: tensor '{}' has shape {} but {} was expected", path_.string(), name, shape_str(t.shape),
         shape_str(shape));
}

std::vector<float> SafeTensors::to_float(const std::string& name, const std::vector<int64_t>& shape) const {
  const TensorInfo& t = info(name);
  if (!shape.empty()) check_shape(name, shape);
  const size_t n = t.numel();
  std::vector<float> out(n);
  const uint8_t* src = map_ + data_start_ + t.begin;
  switch (t.dtype) {
    case StDType::F32: std::memcpy(out.data(), src, n * 4); break;
    case StDType::F16:
      for (size_t i = 0; i < n; ++i) {
        uint16_t h;
        std::memcpy(&h, src + 2 * i, 2);
        out[i] = half_to_float(h);
      }
      break;
    case StDType::BF16:
      for (size_t i = 0; i < n; ++i) {
        uint16_t h;
        std::memcpy(&h, src + 2 * i, 2);
        out[i] = bf16_to_float(h);
      }
      break;
    default:
      fail("{}: tensor '{}' has dtype {}; only F32, F16 and BF16 are supported", path_.string(), name, t.dtype_name);
  }
  return out;
}

void write_safetensors(const std::filesystem::path& path, const std::vector<TensorToWrite>& tensors, StDType dtype,
                       const std::map<std::string, std::string>& metadata) {
  nlohmann::json h = nlohmann::json::object();
  if (!metadata.empty()) h["__metadata__"] = metadata;
  const char* dn = dtype == StDType::F32 ? "F32" : dtype == StDType::F16 ? "F16" : "BF16";
  size_t off = 0;
  for (auto& t : tensors) {
    size_t n = 1;
    for (auto d : t.shape) n *= size_t(d);
    h[t.name] = {{"dtype", dn}, {"shape", t.shape}, {"data_offsets", {off, off + n * dtype_bytes(dtype)}}};
    off += n * dtype_bytes(dtype);
  }
  std::string hs = h.dump();
  while ((8 + hs.size()) % 8) hs += ' ';
  std::vector<uint8_t> buf(8 + hs.size() + off);
  uint64_t hl = hs.size();
  for (int i = 0; i < 8; ++i) buf[i] = uint8_t(hl >> (8 * i));
  std::memcpy(buf.data() + 8, hs.data(), hs.size());
  uint8_t* dst = buf.data() + 8 + hs.size();
  for (auto& t : tensors) {
    size_t n = 1;
    for (auto d : t.shape) n *= size_t(d);
    for (size_t i = 0; i < n; ++i) {
      if (dtype == StDType::F32) {
        std::memcpy(dst, &t.data[i], 4);
        dst += 4;
      } else {
        uint16_t v;
        if (dtype == StDType::F16) {
          v = float_to_half(t.data[i]);
        } else {  // BF16 with round-to-nearest-even
          uint32_t u;
          std::memcpy(&u, &t.data[i], 4);
          v = uint16_t((u + 0x7fff + ((u >> 16) & 1)) >> 16);
        }
        std::memcpy(dst, &v, 2);
        dst += 2;
      }
    }
  }
  atomic_write_bytes(path, buf.data(), buf.size());
}

}  // namespace hgs::nn
