// File helpers: whole-file reads with clear errors, and atomic writes so that a failed or killed command never
// leaves partial output behind: the data goes to an unnamed file in the destination folder (Linux O_TMPFILE),
// is flushed to the disk (fsync), and only then gets its name (linkat, or link under a temporary name + rename
// when it replaces a file). A process killed at any moment (SIGKILL) leaves the old file or the new one, never
// a torn one. The one trace a kill can leave is a complete copy `<name>.hgs-replace` (killed between the link
// and the rename of a replacement), which the next write of that output removes; file systems without
// O_TMPFILE use a named temp file `<name>.tmpXXXXXXXX` that a kill may leave behind (possibly partial), never
// under the output's name. Disk full, a file size limit (RLIMIT_FSIZE)
// or a read-only folder fail with a one-line hgs::Error naming the file.
#pragma once
#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace hgs {
namespace fs = std::filesystem;

std::vector<uint8_t> read_file_bytes(const fs::path& path);
std::string read_file_text(const fs::path& path);

// Calls `write(tmp_path)` (which creates or truncates tmp_path and writes the whole file, reporting its own
// errors), then flushes it and gives it the name `path`. Nothing appears under `path` if `write` throws.
// Suffix of the complete copy a replacement is linked under just before its rename (see above).
inline constexpr const char* kReplaceSuffix = ".hgs-replace";
void atomic_write(const fs::path& path, const std::function<void(const fs::path&)>& write);
void atomic_write_bytes(const fs::path& path, const void* data, size_t size);
void atomic_write_text(const fs::path& path, const std::string& text);

// Creates `dir` (and parents); fails with a clear error if it exists as a file or cannot be made.
void ensure_dir(const fs::path& dir);

}  // namespace hgs
