// Client's calls for working together: the history, undo and redo,
// checkpoints, presence and the history's export.

#include "filigree/client.h"
#include "unary_call.h"

namespace filigree {

v1::History Client::history(const std::string& session_id, const std::string& token, std::uint32_t newest) {
  v1::GetHistoryRequest request;
  request.set_session_id(session_id);
  request.set_newest(newest);
  return unary_call(*stub_, &v1::Filigree::Stub::GetHistory, session_id, token, request, routing_, call_timeout_);
}

namespace {

// Undo and Redo take the same request.
v1::UndoRequest undo_request(const std::string& session_id, const std::string& client_name, bool force) {
  v1::UndoRequest request;
  request.set_session_id(session_id);
  request.set_client_name(client_name);
  request.set_force(force);
  return request;
}

}  // namespace

EditOutcome Client::undo(const std::string& session_id, const std::string& token, const std::string& client_name,
                         bool force) {
  return to_edit_outcome(unary_call(*stub_, &v1::Filigree::Stub::Undo, session_id, token,
                                    undo_request(session_id, client_name, force), routing_, call_timeout_));
}

EditOutcome Client::redo(const std::string& session_id, const std::string& token, const std::string& client_name,
                         bool force) {
  return to_edit_outcome(unary_call(*stub_, &v1::Filigree::Stub::Redo, session_id, token,
                                    undo_request(session_id, client_name, force), routing_, call_timeout_));
}

v1::Checkpoint Client::create_checkpoint(const std::string& session_id, const std::string& token,
                                         const std::string& name, const std::string& client_name) {
  v1::CreateCheckpointRequest request;
  request.set_session_id(session_id);
  request.set_name(name);
  request.set_client_name(client_name);
  return unary_call(*stub_, &v1::Filigree::Stub::CreateCheckpoint, session_id, token, request, routing_,
                    call_timeout_);
}

EditOutcome Client::restore_checkpoint(const std::string& session_id, const std::string& token,
                                       std::uint64_t checkpoint, const std::string& client_name) {
  v1::RestoreCheckpointRequest request;
  request.set_session_id(session_id);
  request.set_checkpoint(checkpoint);
  request.set_client_name(client_name);
  return to_edit_outcome(unary_call(*stub_, &v1::Filigree::Stub::RestoreCheckpoint, session_id, token, request,
                                    routing_, call_timeout_));
}

v1::CheckpointDiff Client::diff_checkpoint(const std::string& session_id, const std::string& token,
                                           std::uint64_t checkpoint) {
  v1::DiffCheckpointRequest request;
  request.set_session_id(session_id);
  request.set_checkpoint(checkpoint);
  return unary_call(*stub_, &v1::Filigree::Stub::DiffCheckpoint, session_id, token, request, routing_,
                    call_timeout_);
}

std::unique_ptr<PresenceWatcher> Client::watch_presence(const std::string& session_id, const std::string& token,
                                                        const std::string& client_name, Reconnect reconnect) {
  v1::WatchPresenceRequest request;
  request.set_session_id(session_id);
  request.set_client_name(client_name);
  return std::unique_ptr<PresenceWatcher>(
      new PresenceWatcher(*stub_, std::move(request), token, routing_, std::move(reconnect)));
}

void Client::set_presence(const std::string& session_id, const std::string& token, const std::string& client_name,
                          const std::optional<PresencePointer>& pointer) {
  v1::SetPresenceRequest request;
  request.set_session_id(session_id);
  request.set_client_name(client_name);
  if (pointer) {
    request.set_has_pointer(true);
    request.set_pointer_x(pointer->position[0]);
    request.set_pointer_y(pointer->position[1]);
    request.set_pointer_z(pointer->position[2]);
    request.set_pointer_vertex(pointer->vertex);
  }
  unary_call(*stub_, &v1::Filigree::Stub::SetPresence, session_id, token, request, routing_, call_timeout_);
}

std::unique_ptr<HistoryExport> Client::export_history(const std::string& session_id, const std::string& token,
                                                      std::vector<float> rest_positions, std::uint64_t from_entry,
                                                      std::uint64_t to_entry) {
  v1::ExportHistoryRequest request;
  request.set_session_id(session_id);
  request.set_from_entry(from_entry);
  request.set_to_entry(to_entry);
  return std::unique_ptr<HistoryExport>(
      new HistoryExport(*stub_, request, token, routing_, std::move(rest_positions)));
}

}  // namespace filigree
