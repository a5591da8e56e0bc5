#include "viewer/static_files.h"

#include <unistd.h>

#include <array>
#include <system_error>

namespace hgs::viewer {
namespace fs = std::filesystem;

fs::path default_static_dir() {
  std::array<char, 4096> buf{};
  const ssize_t n = ::readlink("/proc/self/exe", buf.data(), buf.size() - 1);
  if (n <= 0) return fs::path("viewer");
  return fs::path(std::string(buf.data(), size_t(n))).parent_path() / "viewer";
}

std::optional<fs::path> resolve_static(const fs::path& root, const std::string& url_path) {
  if (url_path.empty() || url_path[0] != '/') return std::nullopt;
  if (url_path.find('\0') != std::string::npos || url_path.find('\\') != std::string::npos) return std::nullopt;
  // Reject any "." or ".." segment outright (before touching the file system).
  size_t start = 1;
  while (start <= url_path.size()) {
    size_t end = url_path.find('/', start);
    if (end == std::string::npos) end = url_path.size();
    const std::string seg = url_path.substr(start, end - start);
    if (seg == "." || seg == "..") return std::nullopt;
    start = end + 1;
  }
  std::error_code ec;
  const fs::path base = fs::canonical(root, ec);
  if (ec) return std::nullopt;
  fs::path p = base / fs::path(url_path.substr(1));
  if (fs::is_directory(p, ec)) p /= "index.html";
  const fs::path real = fs::canonical(p, ec);  // resolves symlinks: must still lie under the root
  if (ec || !fs::is_regular_file(real, ec)) return std::nullopt;
  auto r = real.begin();
  for (auto b = base.begin(); b != base.end(); ++b, ++r)
    if (r == real.end() || *r != *b) return std::nullopt;
  return real;
}

const char* mime_type(const fs::path& file) {
  const std::string e = file.extension().string();
  if (e == ".html") return "text/html; charset=utf-8";
  if (e == ".js" || e == ".mjs") return "text/javascript; charset=utf-8";
  if (e == ".css") return "text/css; charset=utf-8";
  if (e == ".json" || e == ".map") return "application/json";
  if (e == ".png") return "image/png";
  if (e == ".svg") return "image/svg+xml";
  if (e == ".ico") return "image/x-icon";
  if (e == ".wasm") return "application/wasm";
  if (e == ".ply") return "application/octet-stream";
  return "application/octet-stream";
}

}  // namespace hgs::viewer
