#include "server/state/session_store.h"

namespace filigree::server {
namespace {

std::string describe(const std::string& session, const std::string& owner, const std::string& address,
                     std::int64_t retry_after, bool moving_here) {
  const std::string retry = "retry in " + std::to_string(retry_after) + " ms";
  if (address.empty())
    return "session " + session + " was served by replica " + owner + ", which is not responding; its lease expires in " +
           std::to_string(retry_after) + " ms, then any replica takes the session over: " + retry;
  return "session " + session + " is served by replica " + owner + " at " + address +
         (moving_here ? "; it is being handed over to this replica: " + retry : ": call that replica");
}

}  // namespace

SessionElsewhere::SessionElsewhere(const std::string& session, std::string owner, std::string address,
                                   std::int64_t retry_after, bool moving_here)
    : std::runtime_error(describe(session, owner, address, retry_after, moving_here)),
      owner_id(std::move(owner)),
      owner_address(std::move(address)),
      retry_after_ms(retry_after) {}

}  // namespace filigree::server
