#include "server/turns.h"

#include <algorithm>

namespace filigree::server {

Turns::Turns(unsigned limit) : limit_(std::max(1u, limit)) {}

void Turns::acquire() {
  std::unique_lock lock(mutex_);
  ++waiting_;
  freed_.wait(lock, [&] { return held_ < limit_; });
  --waiting_;
  ++held_;
}

void Turns::release() {
  std::lock_guard lock(mutex_);
  --held_;
  freed_.notify_one();
}

std::size_t Turns::waiting() const {
  std::lock_guard lock(mutex_);
  return waiting_;
}

}  // namespace filigree::server
