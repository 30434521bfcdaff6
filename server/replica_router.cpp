#include "server/replica_router.h"

#include <functional>
#include <string>

#include <grpcpp/create_channel.h>
#include <grpcpp/security/credentials.h>
#include <grpcpp/support/channel_arguments.h>

#include "filigree/channel_arguments.h"
#include "server/session_registry.h"

namespace filigree::server {

ReplicaRouter::ReplicaRouter(SessionRegistry& registry, std::shared_ptr<grpc::ChannelCredentials> credentials)
    : registry_(registry), credentials_(std::move(credentials)) {}

std::shared_ptr<grpc::Channel> ReplicaRouter::channel_for(const std::string& session_id) {
  if (!registry_.store().shared()) return nullptr;
  SessionLocation where;
  try {
    where = registry_.locate(session_id);
  } catch (const std::exception&) {
    return nullptr;
  }
  if (!where.exists || where.here || where.address.empty()) return nullptr;
  // Sessions are spread over several connections to the owner: one HTTP/2
  // connection carries at most --max-streams-per-connection calls at once,
  // and browsers' Watch streams through this replica would queue past it.
  constexpr std::size_t kConnectionsPerReplica = 16;
  const std::string key = where.address + "#" + std::to_string(std::hash<std::string>{}(session_id) % kConnectionsPerReplica);
  std::lock_guard lock(mutex_);
  auto& channel = channels_[key];
  if (!channel) {
    // A client's settings (SessionInfo of a large mesh unlimited, the owner
    // enforces its limits; frames come back with the fixed frame window).
    grpc::ChannelArguments args = frame_channel_arguments();
    args.SetMaxSendMessageSize(-1);
    args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);  // its own connection, not one shared by equal channels
    channel = grpc::CreateCustomChannel(where.address, credentials_, args);
  }
  return channel;
}

}  // namespace filigree::server
