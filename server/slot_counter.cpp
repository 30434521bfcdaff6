#include "server/slot_counter.h"

namespace filigree::server {

std::shared_ptr<void> SlotCounter::take(const std::string& key, std::uint64_t limit) {
  {
    std::lock_guard lock(mutex_);
    std::uint64_t& taken = taken_[key];
    if (limit != 0 && taken >= limit) {
      if (taken == 0) taken_.erase(key);
      return nullptr;
    }
    ++taken;
  }
  // Non-null, so that callers can tell a place from a refusal; the deleter
  // gives the place back.
  return std::shared_ptr<void>(static_cast<void*>(this), [this, key](void*) {
    std::lock_guard lock(mutex_);
    if (--taken_[key] == 0) taken_.erase(key);
  });
}

}  // namespace filigree::server
