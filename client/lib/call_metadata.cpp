#include "filigree/call_metadata.h"

namespace filigree {

void set_session_metadata(grpc::ClientContext& context, const std::string& session_id, const std::string& token,
                          Routing routing) {
  // gRPC requires lower-case metadata keys.
  if (!token.empty()) context.AddMetadata("x-filigree-token", token);
  if (!session_id.empty()) context.AddMetadata("x-session-id", session_id);
  if (routing == Routing::kDirect) context.AddMetadata("x-filigree-route", "direct");
}

}  // namespace filigree
