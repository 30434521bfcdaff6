#pragma once
// CreateSession: an upload, its checks and preprocessing, and the session it becomes.

#include <grpcpp/grpcpp.h>

#include "filigree/v1/filigree.pb.h"

namespace filigree::server {

class FiligreeService;

// A CreateSession call's reactor. Deletes itself when the call is done.
grpc::ServerBidiReactor<v1::CreateSessionRequest, v1::CreateSessionResponse>* new_create_reactor(
    FiligreeService& service, grpc::CallbackServerContext* context);

}  // namespace filigree::server
