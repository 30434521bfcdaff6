#pragma once
// Where a call for a session should go when replicas share state: nowhere
// else if this replica serves it (or nobody does: it takes the session),
// else a channel to the replica that does. The gRPC-Web bridge uses it, so a
// browser whose HTTP load balancer picked another replica than the engines'
// gRPC load balancer reaches the session without moving it.

#include <map>
#include <memory>
#include <mutex>
#include <string>

#include <grpcpp/channel.h>
#include <grpcpp/security/credentials.h>

namespace filigree::server {

class SessionRegistry;

class ReplicaRouter {
 public:
  // `credentials`: how to reach the other replicas (peer_credentials() in
  // tls_files.h): plaintext, or TLS as they serve it.
  ReplicaRouter(SessionRegistry& registry, std::shared_ptr<grpc::ChannelCredentials> credentials);
  // nullptr: serve it here. Never throws (a store error serves it here,
  // where the call then fails with its own clear status).
  std::shared_ptr<grpc::Channel> channel_for(const std::string& session_id);

 private:
  SessionRegistry& registry_;
  const std::shared_ptr<grpc::ChannelCredentials> credentials_;
  std::mutex mutex_;
  std::map<std::string, std::shared_ptr<grpc::Channel>> channels_;  // by "address#connection"
};

}  // namespace filigree::server
