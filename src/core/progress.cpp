#include "core/progress.h"

#include <fmt/format.h>
#include <unistd.h>

#include <cstdio>

namespace hgs {

Progress::Progress(std::string label, long total, bool enabled)
    : label_(std::move(label)), total_(total > 0 ? total : 1), enabled_(enabled), tty_(isatty(2)) {
  start_ = last_print_ = std::chrono::steady_clock::now();
}

Progress::~Progress() {
  if (!finished_ && enabled_ && tty_ && last_printed_done_ >= 0) std::fputc('\n', stderr);
}

double Progress::elapsed_seconds() const {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
}

std::string format_duration(double s) {
  if (s < 0) s = 0;
  if (s < 60) return fmt::format("{:.1f}s", s);
  long t = static_cast<long>(s + 0.5);
  if (t < 3600) return fmt::format("{}m{:02d}s", t / 60, t % 60);
  return fmt::format("{}h{:02d}m", t / 3600, (t % 3600) / 60);
}

void Progress::update(long done, const std::string& status) {
  if (!enabled_) return;
  auto now = std::chrono::steady_clock::now();
  double since = std::chrono::duration<double>(now - last_print_).count();
  if (tty_) {
    if (since < 0.1 && done < total_) return;
  } else {
    long step = std::max(1L, total_ / 10);
    bool crossed = last_printed_done_ < 0 || done / step != last_printed_done_ / step;
    if (!(crossed || since > 30 || done >= total_)) return;
  }
  last_print_ = now;
  last_printed_done_ = done;
  double el = elapsed_seconds();
  double frac = double(done) / double(total_);
  double eta = done > 0 ? el * (1 - frac) / frac : 0;
  const int width = 24;
  int fill = static_cast<int>(frac * width);
  std::string bar(fill, '#');
  bar += std::string(width - fill, '.');
  std::string line = fmt::format("{} [{}] {}/{} {:3.0f}% {} ETA {}{}{}", label_, bar, done, total_, frac * 100,
                                 format_duration(el), format_duration(eta), status.empty() ? "" : "  ", status);
  if (tty_) fmt::print(stderr, "\r{}\x1b[K", line);
  else fmt::print(stderr, "{}\n", line);
  std::fflush(stderr);
}

void Progress::note(const std::string& line) {
  if (!enabled_) return;
  if (tty_) fmt::print(stderr, "\r{}\x1b[K\n", line);
  else fmt::print(stderr, "{}\n", line);
  std::fflush(stderr);
  last_print_ = std::chrono::steady_clock::time_point{};  // redraw the bar at the next update
}

void Progress::finish(const std::string& status) {
  if (!enabled_ || finished_) return;
  // Print the final state unless that exact line is already on screen (non-TTY logs).
  if (tty_ || last_printed_done_ != total_ || !status.empty()) {
    last_printed_done_ = -1;
    last_print_ = std::chrono::steady_clock::time_point{};
    update(total_, status);
  }
  if (tty_) std::fputc('\n', stderr);
  finished_ = true;
}

}  // namespace hgs
