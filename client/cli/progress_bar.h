#pragma once
// A progress bar on stderr: redrawn in place on a terminal, a line per 10%
// otherwise (so logs of non-interactive runs stay short).

#include <chrono>
#include <string>

#include "util/time_left.h"

namespace filigree::cli {

class ProgressBar {
 public:
  explicit ProgressBar(std::string label);
  ~ProgressBar();
  void update(double fraction);
  void finish();

 private:
  std::string label_;
  bool tty_;
  bool finished_ = false;
  int last_percent_ = -1;
  std::chrono::steady_clock::time_point start_;
  TimeLeft left_;
};

}  // namespace filigree::cli
