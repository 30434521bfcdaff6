#pragma once
// The metadata every Filigree call carries (proto/filigree/v1/filigree.proto,
// "Authentication").

#include <string>

#include <grpcpp/client_context.h>

namespace filigree {

// How calls reach a replica when there are several (DESIGN §4).
enum class Routing {
  // Through a load balancer that routes by x-session-id: the replica that
  // receives a session's calls takes the session over if another serves it.
  kLoadBalanced,
  // Straight to the replica Client::locate() named: a replica that does not
  // serve the session answers UNAVAILABLE naming the one that does (trailing
  // metadata x-filigree-owner) and leaves the session where it is.
  kDirect,
};

// Adds `x-filigree-token: token` (skipped when empty: ListSessions and
// CreateSession need none) and `x-session-id: session_id` (skipped when
// empty), the key a load balancer routes by. For calls made on
// Client::stub() directly; the Client's own calls do it themselves.
// With Routing::kDirect, also `x-filigree-route: direct`.
void set_session_metadata(grpc::ClientContext& context, const std::string& session_id, const std::string& token,
                          Routing routing = Routing::kLoadBalanced);

}  // namespace filigree
