#pragma once
// GetRestMesh: a session's rest mesh in parts of bounded size, for meshes
// whose SessionInfo would not fit in one message (RestMesh.in_parts).

#include <grpcpp/grpcpp.h>

#include "filigree/v1/filigree.pb.h"

namespace filigree::server {

class FiligreeService;

// A GetRestMesh call's reactor. Deletes itself when the call is done.
grpc::ServerWriteReactor<v1::RestMeshPart>* new_rest_mesh_reactor(FiligreeService& service,
                                                                  grpc::CallbackServerContext* context,
                                                                  const v1::GetRestMeshRequest& request);

}  // namespace filigree::server
