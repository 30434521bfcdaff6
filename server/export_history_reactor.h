#pragma once
// ExportHistory: the state after each history entry of a range, deformed at
// full detail, one message at a time.

#include <grpcpp/grpcpp.h>

#include "filigree/v1/filigree.pb.h"

namespace filigree::server {

class FiligreeService;

grpc::ServerWriteReactor<v1::HistoryFrame>* new_export_history_reactor(FiligreeService& service,
                                                                       grpc::CallbackServerContext* context,
                                                                       const v1::ExportHistoryRequest& request);

}  // namespace filigree::server
