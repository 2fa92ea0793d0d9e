#include "artisan/sensors/replay.hpp"

#include <algorithm>
#include <variant>

#include "artisan/core/io/geometry_file.hpp"

namespace artisan::sensors {

namespace {

bool is_recording(const std::filesystem::path& p) {
  std::string ext = p.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext == ".ari" || ext == ".ply" || ext == ".pcd";
}

}  // namespace

ReplaySensor::ReplaySensor(const std::string& name, const std::filesystem::path& folder) {
  std::error_code ec;
  if (!std::filesystem::is_directory(folder, ec)) throw Error("replay sensor '" + name + "': folder " + folder.string() + " does not exist");
  for (const auto& e : std::filesystem::directory_iterator(folder))
    if (e.is_regular_file() && is_recording(e.path())) files_.push_back(e.path());
  if (files_.empty()) throw Error("replay sensor '" + name + "': folder " + folder.string() + " holds no .ari, .ply or .pcd file");
  std::sort(files_.begin(), files_.end());
  description_.name = name;
  description_.kind = "replay";
  description_.range = true;
  description_.description = "recorded acquisitions from " + folder.string() + " (" + std::to_string(files_.size()) + " files)";
  std::string names;
  for (const auto& f : files_) {
    if (names.size() > 400) {
      names += ", ...";
      break;
    }
    names += (names.empty() ? "" : ", ") + f.filename().string();
  }
  description_.parameters = {{"file", "string", "", "", "the recording to serve (default: the next, cycling): " + names}};
}

Acquisition ReplaySensor::do_acquire(const AcquireRequest& request, const CancelToken& cancel) {
  std::filesystem::path file;
  const auto it = request.params.find("file");
  if (it != request.params.end()) {
    for (const auto& f : files_)
      if (f.filename() == it->second || f.stem() == it->second) file = f;
    if (file.empty())
      throw SensorError(ErrorCode::kBadParameter, "sensor '" + description_.name + "': no recording '" + it->second + "'");
  } else {
    file = files_[next_.fetch_add(1) % files_.size()];
  }
  cancel.check("sensor '" + description_.name + "'");
  io::Geometry g = io::load_geometry(file);
  auto* range = std::get_if<RangeImage>(&g);
  if (!range)
    throw SensorError(ErrorCode::kSensorFailure,
                      "sensor '" + description_.name + "': " + file.string() + " holds a " + io::kind_name(g) + ", not a range image");
  Acquisition out;
  out.range = std::move(*range);
  return out;
}

}  // namespace artisan::sensors
