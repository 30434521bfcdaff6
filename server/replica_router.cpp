#include "server/replica_router.h"

#include <functional>
#include <string>

#include <grpcpp/create_channel.h>
#include <grpcpp/security/credentials.h>
#include <grpcpp/support/channel_arguments.h>

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
    grpc::ChannelArguments args;
    args.SetMaxReceiveMessageSize(-1);  // SessionInfo of a large mesh; the owner enforces its limits
    args.SetMaxSendMessageSize(-1);
    args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);  // its own connection, not one shared by equal channels
    // Frames come back through this channel: a fixed window, as the client
    // library's (client/lib/include/filigree/channel_arguments.h says why).
    args.SetInt(GRPC_ARG_HTTP2_BDP_PROBE, 0);
    args.SetInt(GRPC_ARG_HTTP2_STREAM_LOOKAHEAD_BYTES, 4 << 20);
    channel = grpc::CreateCustomChannel(where.address, credentials_, args);
  }
  return channel;
}

}  // namespace filigree::server
