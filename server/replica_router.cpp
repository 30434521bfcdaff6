#include "server/replica_router.h"

#include <grpcpp/create_channel.h>
#include <grpcpp/security/credentials.h>
#include <grpcpp/support/channel_arguments.h>

#include "server/session_registry.h"

namespace filigree::server {

ReplicaRouter::ReplicaRouter(SessionRegistry& registry) : registry_(registry) {}

std::shared_ptr<grpc::Channel> ReplicaRouter::channel_for(const std::string& session_id) {
  if (!registry_.store().shared()) return nullptr;
  SessionLocation where;
  try {
    where = registry_.locate(session_id);
  } catch (const std::exception&) {
    return nullptr;
  }
  if (!where.exists || where.here || where.address.empty()) return nullptr;
  std::lock_guard lock(mutex_);
  auto& channel = channels_[where.address];
  if (!channel) {
    grpc::ChannelArguments args;
    args.SetMaxReceiveMessageSize(-1);  // SessionInfo of a large mesh; the owner enforces its limits
    args.SetMaxSendMessageSize(-1);
    channel = grpc::CreateCustomChannel(where.address, grpc::InsecureChannelCredentials(), args);
  }
  return channel;
}

}  // namespace filigree::server
