#include "bench/soak/failures.h"

#include <cstdio>

namespace filigree::soak {

void Failures::add(const std::string& why) {
  std::lock_guard lock(mutex_);
  ++count_;
  if (reasons_.size() < kKept) {
    reasons_.push_back(why);
    std::fprintf(stderr, "soak: FAILURE: %s\n", why.c_str());
  }
}

std::size_t Failures::count() const {
  std::lock_guard lock(mutex_);
  return count_;
}

std::vector<std::string> Failures::reasons() const {
  std::lock_guard lock(mutex_);
  return reasons_;
}

}  // namespace filigree::soak
