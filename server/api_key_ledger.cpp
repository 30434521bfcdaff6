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
  return streams_.take(key, limit);
}

}  // namespace filigree::server
