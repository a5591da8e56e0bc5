#include "core/fs.h"

#include <fstream>
#include <random>

#include "core/error.h"

namespace hgs {

std::vector<uint8_t> read_file_bytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) {
    if (!fs::exists(path)) fail("{}: file not found", path.string());
    fail("{}: cannot open for reading", path.string());
  }
  std::streamsize n = in.tellg();
  in.seekg(0);
  std::vector<uint8_t> buf(static_cast<size_t>(n));
  if (n > 0 && !in.read(reinterpret_cast<char*>(buf.data()), n)) fail("{}: read error", path.string());
  return buf;
}

std::string read_file_text(const fs::path& path) {
  auto b = read_file_bytes(path);
  return std::string(b.begin(), b.end());
}

void atomic_write(const fs::path& path, const std::function<void(const fs::path&)>& write) {
  fs::path dir = path.parent_path();
  if (!dir.empty()) ensure_dir(dir);
  static thread_local std::mt19937_64 rng{std::random_device{}()};
  fs::path tmp = path;
  tmp += fmt::format(".tmp{:08x}", static_cast<uint32_t>(rng()));
  try {
    write(tmp);
    std::error_code ec;
    fs::rename(tmp, path, ec);
    if (ec) fail("{}: cannot write ({})", path.string(), ec.message());
  } catch (...) {
    std::error_code ec;
    fs::remove(tmp, ec);
    throw;
  }
}

void atomic_write_bytes(const fs::path& path, const void* data, size_t size) {
  atomic_write(path, [&](const fs::path& tmp) {
    std::ofstream out(tmp, std::ios::binary);
    if (!out) fail("{}: cannot open for writing", path.string());
    out.write(static_cast<const char*>(data), static_cast<std::streamsize>(size));
    if (!out) fail("{}: write error (disk full?)", path.string());
  });
}

void atomic_write_text(const fs::path& path, const std::string& text) {
  atomic_write_bytes(path, text.data(), text.size());
}

void ensure_dir(const fs::path& dir) {
  std::error_code ec;
  if (fs::exists(dir, ec)) {
    if (!fs::is_directory(dir, ec)) fail("{}: exists but is not a directory", dir.string());
    return;
  }
  fs::create_directories(dir, ec);
  if (ec) fail("{}: cannot create directory ({})", dir.string(), ec.message());
}

}  // namespace hgs
