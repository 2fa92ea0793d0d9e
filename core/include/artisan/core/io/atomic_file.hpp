#pragma once
// File helpers shared by the readers and writers.
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

namespace artisan::io {

/// The file's extension in lower case, with its dot (".ply"); empty when there is none.
std::string lower_extension(const std::filesystem::path& path);

/// The whole file; throws artisan::FileError when it cannot be read.
std::vector<uint8_t> read_file_bytes(const std::filesystem::path& path);

/// Writes to a temporary file beside `path`, flushes, then renames over `path`: a failure
/// leaves the destination as it was. Throws artisan::FileError.
void write_file_atomically(const std::filesystem::path& path, std::span<const uint8_t> bytes);

}  // namespace artisan::io
