// safetensors reader: the file is memory-mapped read-only; the header (8-byte little-endian length + JSON
// object {name: {dtype, shape, data_offsets: [begin, end]}, "__metadata__": {...}}) is parsed with
// nlohmann-json and checked against the file size. Tensors are returned as views into the mapping or
// converted to float32 (F32, F16, BF16 supported). Every error is one line naming the file and the tensor.
#pragma once
#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

namespace hgs::nn {

enum class StDType { F32, F16, BF16, Other };

struct TensorInfo {
  std::string name;
  StDType dtype = StDType::F32;
  std::string dtype_name;      // as written in the header ("F32", "F16", ...)
  std::vector<int64_t> shape;  // row-major
  size_t begin = 0, end = 0;   // byte offsets into the data section
  size_t numel() const;
};

class SafeTensors {
 public:
  // Maps `path` and validates the header. Throws hgs::Error on any problem.
  explicit SafeTensors(const std::filesystem::path& path);
  ~SafeTensors();
  SafeTensors(const SafeTensors&) = delete;
  SafeTensors& operator=(const SafeTensors&) = delete;

  const std::filesystem::path& path() const { return path_; }
  bool has(const std::string& name) const { return tensors_.count(name) > 0; }
  const TensorInfo& info(const std::string& name) const;  // throws "missing tensor"
  std::vector<std::string> names() const;
  const std::map<std::string, std::string>& metadata() const { return metadata_; }

  // The tensor converted to float32; if `shape` is non-empty the stored shape must equal it (use -1 for any
  // size in one dimension).
  std::vector<float> to_float(const std::string& name, const std::vector<int64_t>& shape = {}) const;
  // Checks the shape of a tensor against `shape` (-1 = any) and throws a one-line error otherwise.
  void check_shape(const std::string& name, const std::vector<int64_t>& shape) const;

 private:
  std::filesystem::path path_;
  const uint8_t* map_ = nullptr;
  size_t map_size_ = 0;
  size_t data_start_ = 0;  // 8 + header length
  std::map<std::string, TensorInfo> tensors_;
  std::map<std::string, std::string> metadata_;
};

std::string shape_str(const std::vector<int64_t>& shape);  // "[768, 3, 16, 16]"

// Writes a safetensors file (atomic) from float32 tensors stored as `dtype` (F32, F16 or BF16). Used by the
// benchmarks and tests to make model files.
struct TensorToWrite {
  std::string name;
  std::vector<int64_t> shape;
  const float* data;
};
void write_safetensors(const std::filesystem::path& path, const std::vector<TensorToWrite>& tensors,
                       StDType dtype = StDType::F32, const std::map<std::string, std::string>& metadata = {});

}  // namespace hgs::nn
