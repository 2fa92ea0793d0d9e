#pragma once
// The time of an edit or an addition as the workspace records it: ISO 8601, UTC, to the second.
#include <chrono>
#include <ctime>
#include <string>

namespace artisan::worldmodel {

inline std::string utc_now() {
  const std::time_t t = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

}  // namespace artisan::worldmodel
