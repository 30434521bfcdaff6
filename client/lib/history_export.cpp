#include "filigree/history_export.h"

#include "filigree/client_error.h"

namespace filigree {

HistoryExport::HistoryExport(v1::Filigree::Stub& stub, const v1::ExportHistoryRequest& request,
                             const std::string& token, Routing routing, std::vector<float> rest_positions)
    : decoder_(std::move(rest_positions)) {
  set_session_metadata(context_, request.session_id(), token, routing);
  stream_ = stub.ExportHistory(&context_, request);
}

HistoryExport::~HistoryExport() {
  if (status_) return;
  cancel();
  finish();
}

std::optional<HistoryState> HistoryExport::read() {
  if (status_) return std::nullopt;
  v1::HistoryFrame message;
  if (!stream_->Read(&message)) {
    status_ = stream_->Finish();
    return std::nullopt;
  }
  HistoryState state;
  state.entry = message.entry();
  state.author = message.author();
  state.time = message.time();
  state.version = message.frame().version();
  state.base_pose.assign(message.base_pose().begin(), message.base_pose().end());
  try {
    DecodedFrame decoded = decoder_.decode(message.frame());
    state.positions = std::move(decoded.positions);
    state.max_error = decoded.max_error;
  } catch (const ClientError&) {
    cancel();  // the rest would not decode either
    throw;
  }
  return state;
}

void HistoryExport::cancel() { context_.TryCancel(); }

grpc::Status HistoryExport::finish() {
  while (!status_) {
    v1::HistoryFrame ignored;
    if (!stream_->Read(&ignored)) status_ = stream_->Finish();
  }
  return *status_;
}

}  // namespace filigree
