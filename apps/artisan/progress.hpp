#pragma once
// Progress of a long command on stderr: on a terminal a bar with the rate and the time left,
// redrawn in place; otherwise (a log, a pipe) a plain line at most every 2 s and at the end.
// Silent with --quiet or --json, and for a single step.
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <functional>
#include <string>

namespace artisan::cli {

class Progress {
 public:
  /// `total` steps (0: given by the first update(done, total, item)).
  Progress(std::string what, size_t total, bool silent)
      : what_(std::move(what)), total_(total), silent_(silent), tty_(::isatty(STDERR_FILENO) == 1) {}
  ~Progress() {
    if (!silent_ && tty_ && drawn_) std::fputc('\n', stderr);
  }
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  /// `done` of the total finished; `item` names the one just finished.
  void update(size_t done, const std::string& item = "") {
    if (silent_ || total_ < 2) return;
    const auto now = Clock::now();
    const double elapsed = std::chrono::duration<double>(now - start_).count();
    const bool last = done >= total_;
    if (!tty_ && !last && std::chrono::duration<double>(now - last_line_).count() < 2.0) return;
    last_line_ = now;
    const double rate = elapsed > 0 ? double(done) / elapsed : 0.0;
    const double left = rate > 0 ? double(total_ - std::min(done, total_)) / rate : 0.0;
    char tail[128];
    std::snprintf(tail, sizeof tail, "%zu/%zu  %.1f/s  %s %.0f s", done, total_, rate, last ? "took" : "left", last ? elapsed : left);
    if (tty_) {
      const int width = 30, filled = int(width * double(done) / double(total_));
      std::fprintf(stderr, "\r%s [%s%s] %s %s\033[K", what_.c_str(), std::string(size_t(filled), '#').c_str(),
                   std::string(size_t(width - filled), '.').c_str(), tail, item.c_str());
      drawn_ = true;
    } else {
      std::fprintf(stderr, "%s: %s %s\n", what_.c_str(), tail, item.c_str());
    }
    std::fflush(stderr);
  }
  void update(size_t done, size_t total, const std::string& item) {
    total_ = total;
    update(done, item);
  }
  /// As a callback for library operations (worldmodel::ProgressFn's form).
  std::function<void(size_t, size_t, const std::string&)> callback() {
    return [this](size_t done, size_t total, const std::string& item) { update(done, total, item); };
  }

 private:
  using Clock = std::chrono::steady_clock;
  std::string what_;
  size_t total_;
  bool silent_, tty_, drawn_ = false;
  Clock::time_point start_ = Clock::now(), last_line_ = Clock::now();
};

}  // namespace artisan::cli
