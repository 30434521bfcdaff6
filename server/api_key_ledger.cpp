#include "server/api_key_ledger.h"

namespace filigree::server {

bool ApiKeyLedger::admit_upload(const std::string& key, std::uint64_t limit) {
  const auto now = std::chrono::steady_clock::now();
  std::lock_guard lock(mutex_);
  auto& times = uploads_[key];
  while (!times.empty() && now - times.front() >= std::chrono::minutes(1)) times.pop_front();
  if (limit != 0 && times.size() >= limit) return false;
  times.push_back(now);
  return true;
}

std::shared_ptr<void> ApiKeyLedger::open_stream(const std::string& key, std::uint64_t limit) {
  {
    std::lock_guard lock(mutex_);
    std::uint64_t& open = streams_[key];
    if (limit != 0 && open >= limit) return nullptr;
    ++open;
  }
  // The handle gives the slot back when the last copy goes (non-null, so
  // that callers can tell it from a refusal).
  struct Slot {
    ApiKeyLedger* ledger;
    std::string key;
    ~Slot() {
      std::lock_guard lock(ledger->mutex_);
      --ledger->streams_[key];
    }
  };
  return std::shared_ptr<Slot>(new Slot{this, key});
}

}  // namespace filigree::server
