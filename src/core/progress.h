// Terminal progress bar with rate and ETA, written to stderr. On a TTY it redraws one line; otherwise (CI,
// logs) it prints a plain line at most every 10% or 30 s. Safe to call from the thread that owns it only.
#pragma once
#include <chrono>
#include <string>

namespace hgs {

class Progress {
 public:
  Progress(std::string label, long total, bool enabled = true);
  ~Progress();
  // Sets the current count and an optional status text (e.g. "loss 0.031 psnr 27.1").
  void update(long done, const std::string& status = "");
  void finish(const std::string& status = "");
  // Prints one line of its own (e.g. a periodic test score) above the bar; the bar is redrawn at the next update.
  void note(const std::string& line);
  double elapsed_seconds() const;

 private:
  std::string label_;
  long total_;
  bool enabled_, tty_, finished_ = false;
  std::chrono::steady_clock::time_point start_, last_print_;
  long last_printed_done_ = -1;
};

std::string format_duration(double seconds);  // "1h02m", "3m05s", "12.3s"

}  // namespace hgs
