#include "cli/progress_bar.h"

#include <algorithm>
#include <cstdio>
#include <unistd.h>

namespace filigree::cli {

ProgressBar::ProgressBar(std::string label)
    : label_(std::move(label)), tty_(isatty(fileno(stderr)) != 0), start_(std::chrono::steady_clock::now()) {}

ProgressBar::~ProgressBar() { finish(); }

void ProgressBar::update(double fraction) {
  const int percent = static_cast<int>(std::clamp(fraction, 0.0, 1.0) * 100.0);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  left_.add(seconds, std::clamp(fraction, 0.0, 1.0));
  if (percent == last_percent_ || (!tty_ && last_percent_ >= 0 && percent / 10 == last_percent_ / 10)) return;
  last_percent_ = percent;
  // "~12s left" once there is an estimate, blank before (the line keeps its width).
  char left[32] = "";
  if (const auto s = left_.seconds(); s && percent < 100) std::snprintf(left, sizeof left, "  ~%.0fs left", *s);
  if (tty_) {
    constexpr int kWidth = 30;
    const int filled = percent * kWidth / 100;
    std::fprintf(stderr, "\r%s [%.*s%*s] %3d%% %6.1fs%-14s", label_.c_str(), filled, "##############################",
                 kWidth - filled, "", percent, seconds, left);
  } else {
    std::fprintf(stderr, "%s %3d%% %6.1fs%s\n", label_.c_str(), percent, seconds, left);
  }
  std::fflush(stderr);
}

void ProgressBar::finish() {
  if (finished_) return;
  finished_ = true;
  if (tty_ && last_percent_ >= 0) std::fputc('\n', stderr);
}

}  // namespace filigree::cli
