#pragma once
// Errors: bad user input and bad files throw these, with a message that names the file, the
// field and the value. Internal invariants use assert instead.
#include <filesystem>
#include <stdexcept>
#include <string>

namespace artisan {

/// Bad input given to Artisan (a value, a file, an identifier). The message says what is wrong.
class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// A file that cannot be read or written, or whose contents are malformed.
/// what() reads "<path>: <reason>".
class FileError : public Error {
 public:
  FileError(const std::filesystem::path& path, const std::string& reason);
  const std::filesystem::path& path() const { return path_; }
  const std::string& reason() const { return reason_; }

 private:
  std::filesystem::path path_;
  std::string reason_;
};

}  // namespace artisan
