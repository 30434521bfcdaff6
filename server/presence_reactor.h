#pragma once
// WatchPresence: a session's presence, streamed (session_presence.cpp).

#include <grpcpp/grpcpp.h>

#include "filigree/v1/filigree.pb.h"

namespace filigree::server {

class FiligreeService;

grpc::ServerWriteReactor<v1::Presence>* new_presence_reactor(FiligreeService& service, grpc::CallbackServerContext* context,
                                                             const v1::WatchPresenceRequest& request);

}  // namespace filigree::server
