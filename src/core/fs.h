// File helpers: whole-file reads with clear errors, and atomic writes (temp file in the same folder, then
// rename) so that a failed command never leaves partial output behind.
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

// Calls `write(tmp_path)` then renames tmp_path to `path`. The temp file is removed if `write` throws.
void atomic_write(const fs::path& path, const std::function<void(const fs::path&)>& write);
void atomic_write_bytes(const fs::path& path, const void* data, size_t size);
void atomic_write_text(const fs::path& path, const std::string& text);

// Creates `dir` (and parents); fails with a clear error if it exists as a file or cannot be made.
void ensure_dir(const fs::path& dir);

}  // namespace hgs
