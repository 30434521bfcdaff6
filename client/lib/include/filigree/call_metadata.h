#pragma once
// The metadata every Filigree call carries (proto/filigree/v1/filigree.proto,
// "Authentication").

#include <string>

#include <grpcpp/client_context.h>

namespace filigree {

// Adds `x-filigree-token: token` (skipped when empty: ListSessions and
// CreateSession need none) and `x-session-id: session_id` (skipped when
// empty), the key a load balancer routes by. For calls made on
// Client::stub() directly; the Client's own calls do it themselves.
void set_session_metadata(grpc::ClientContext& context, const std::string& session_id, const std::string& token);

}  // namespace filigree
