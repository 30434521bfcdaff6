#pragma once
// Places counted per key, each held by a handle until it is released: a
// session's streams, the streams of an API key's sessions, a key's uploads in
// progress and the vertices they will hold.

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>

namespace filigree::server {

class SlotCounter {
 public:
  // A place under `key`, held until the last copy of the handle goes; null
  // (nothing taken) when `limit` places are taken already. limit 0: no limit.
  // The counter must outlive the handles.
  std::shared_ptr<void> take(const std::string& key, std::uint64_t limit);

  // `amount` places at once, if what `held_elsewhere` says plus those taken
  // plus `amount` stays within `limit` (0: no limit); null otherwise.
  // `held_elsewhere` is asked under the counter's lock, so a caller that
  // moves its places elsewhere first and releases them after is counted at
  // least once by every concurrent take: check and take are one step.
  std::shared_ptr<void> take(const std::string& key, std::uint64_t limit, std::uint64_t amount,
                             const std::function<std::uint64_t()>& held_elsewhere);

 private:
  std::mutex mutex_;
  std::map<std::string, std::uint64_t> taken_;  // keys with no place taken are removed
};

}  // namespace filigree::server
