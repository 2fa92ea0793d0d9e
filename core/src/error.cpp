#include "artisan/core/error.hpp"

namespace artisan {

FileError::FileError(const std::filesystem::path& path, const std::string& reason)
    : Error(path.string() + ": " + reason), path_(path), reason_(reason) {}

}  // namespace artisan
