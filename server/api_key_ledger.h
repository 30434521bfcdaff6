#pragma once
// What each API key is using now that the registry cannot count: uploads in
// the last minute and streams open on its sessions.

#include <chrono>
#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <string>

#include "server/slot_counter.h"

namespace filigree::server {

class ApiKeyLedger {
 public:
  // Records an upload by `key` now, unless `limit` (0: none) uploads were
  // recorded in the last 60 s: then false, and nothing is recorded.
  bool admit_upload(const std::string& key, std::uint64_t limit);
  // A slot for a stream on one of `key`'s sessions, held until the returned
  // handle is released; null when `limit` (0: none) streams are open.
  // The ledger must outlive the handles.
  std::shared_ptr<void> open_stream(const std::string& key, std::uint64_t limit);

 private:
  std::mutex mutex_;
  std::map<std::string, std::deque<std::chrono::steady_clock::time_point>> uploads_;
  SlotCounter streams_;
};

}  // namespace filigree::server
