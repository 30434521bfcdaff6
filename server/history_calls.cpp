// FiligreeService's unary calls on a session's edit history, checkpoints and
// presence (proto: GetHistory … SetPresence; session_history.cpp).

#include <cmath>
#include <stdexcept>

#include "server/call_arguments.h"
#include "server/filigree_service.h"
#include "server/pose_request.h"
#include "server/session.h"
#include "server/state/session_store.h"

namespace filigree::server {
namespace {

// A history call's body: its errors as statuses (a job's escaped exception
// would end the process).
grpc::Status guarded(const std::function<void()>& body) {
  try {
    body();
  } catch (const PoseError& e) {
    return {grpc::StatusCode::INVALID_ARGUMENT, e.what()};
  } catch (const std::invalid_argument& e) {
    return {grpc::StatusCode::INVALID_ARGUMENT, e.what()};
  } catch (const std::out_of_range& e) {
    return {grpc::StatusCode::NOT_FOUND, e.what()};
  } catch (const StoreUnavailable& e) {
    return {grpc::StatusCode::UNAVAILABLE, e.what()};
  } catch (const std::exception& e) {
    return {grpc::StatusCode::INTERNAL, e.what()};
  }
  return grpc::Status::OK;
}

// Undo, redo and restore may change the threshold (whole-mesh optimisation
// factorises for seconds): always a job.
bool always(const Session&) { return true; }

}  // namespace

grpc::ServerUnaryReactor* FiligreeService::GetHistory(grpc::CallbackServerContext* context,
                                                      const v1::GetHistoryRequest* request, v1::History* response) {
  const std::size_t newest = request->newest();
  return unary_on_session(context, request->session_id(), Role::kViewer, [=](Session& s) {
    return guarded([&] { *response = s.history(newest); });
  });
}

grpc::ServerUnaryReactor* FiligreeService::Undo(grpc::CallbackServerContext* context, const v1::UndoRequest* request,
                                                v1::UndoResponse* response) {
  return undo_call(context, *request, response, /*redo=*/false);
}

grpc::ServerUnaryReactor* FiligreeService::Redo(grpc::CallbackServerContext* context, const v1::UndoRequest* request,
                                                v1::UndoResponse* response) {
  return undo_call(context, *request, response, /*redo=*/true);
}

grpc::ServerUnaryReactor* FiligreeService::undo_call(grpc::CallbackServerContext* context, const v1::UndoRequest& request,
                                                     v1::UndoResponse* response, bool redo) {
  return unary_on_session(
      context, request.session_id(), Role::kEditor,
      [=, author = request.client_name(), force = request.force()](Session& s) {
        return guarded([&] {
          check_client_name(author);
          *response = s.undo(author, redo, force);
        });
      },
      always);
}

grpc::ServerUnaryReactor* FiligreeService::CreateCheckpoint(grpc::CallbackServerContext* context,
                                                            const v1::CreateCheckpointRequest* request,
                                                            v1::Checkpoint* response) {
  return unary_on_session(context, request->session_id(), Role::kEditor,
                          [=, author = request->client_name(), name = request->name()](Session& s) {
                            return guarded([&] {
                              check_client_name(author);
                              *response = s.create_checkpoint(author, name);
                            });
                          });
}

grpc::ServerUnaryReactor* FiligreeService::RestoreCheckpoint(grpc::CallbackServerContext* context,
                                                             const v1::RestoreCheckpointRequest* request,
                                                             v1::UndoResponse* response) {
  return unary_on_session(
      context, request->session_id(), Role::kEditor,
      [=, author = request->client_name(), id = request->checkpoint()](Session& s) {
        return guarded([&] {
          check_client_name(author);
          *response = s.restore_checkpoint(author, id);
        });
      },
      always);
}

grpc::ServerUnaryReactor* FiligreeService::DiffCheckpoint(grpc::CallbackServerContext* context,
                                                          const v1::DiffCheckpointRequest* request,
                                                          v1::CheckpointDiff* response) {
  return unary_on_session(context, request->session_id(), Role::kViewer, [=, id = request->checkpoint()](Session& s) {
    return guarded([&] { *response = s.diff_checkpoint(id); });
  });
}

grpc::ServerUnaryReactor* FiligreeService::SetPresence(grpc::CallbackServerContext* context,
                                                       const v1::SetPresenceRequest* request, v1::SetPresenceResponse*) {
  const std::string token = metadata(*context, "x-filigree-token");
  return unary_on_session(context, request->session_id(), Role::kViewer, [=, r = *request](Session& s) {
    return guarded([&] {
      check_client_name(r.client_name());
      std::optional<Session::Pointer> pointer;
      if (r.has_pointer()) {
        if (!std::isfinite(r.pointer_x()) || !std::isfinite(r.pointer_y()) || !std::isfinite(r.pointer_z()))
          throw std::invalid_argument("the pointer's position is not finite");
        if (r.pointer_vertex() >= s.vertex_count())
          throw std::invalid_argument("pointer_vertex " + std::to_string(r.pointer_vertex()) + " is out of range: the mesh has " +
                                      std::to_string(s.vertex_count()) + " vertices");
        pointer = Session::Pointer{r.pointer_x(), r.pointer_y(), r.pointer_z(), r.pointer_vertex()};
      }
      s.point(r.client_name(), s.authorize(token), pointer);
    });
  });
}

}  // namespace filigree::server
