#include "server/slot_counter.h"

namespace filigree::server {

std::shared_ptr<void> SlotCounter::take(const std::string& key, std::uint64_t limit) {
  return take(key, limit, 1, [] { return std::uint64_t{0}; });
}

std::shared_ptr<void> SlotCounter::take(const std::string& key, std::uint64_t limit, std::uint64_t amount,
                                        const std::function<std::uint64_t()>& held_elsewhere) {
  {
    std::lock_guard lock(mutex_);
    std::uint64_t& taken = taken_[key];
    if (limit != 0) {
      const std::uint64_t held = held_elsewhere();
      // Written so that no sum can wrap: held + taken + amount > limit.
      if (held > limit || taken > limit - held || amount > limit - held - taken) {
        if (taken == 0) taken_.erase(key);
        return nullptr;
      }
    }
    taken += amount;
  }
  // Non-null, so that callers can tell a place from a refusal; the deleter
  // gives the places back.
  return std::shared_ptr<void>(static_cast<void*>(this), [this, key, amount](void*) {
    std::lock_guard lock(mutex_);
    if ((taken_[key] -= amount) == 0) taken_.erase(key);
  });
}

}  // namespace filigree::server
