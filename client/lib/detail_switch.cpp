#include "detail_switch.h"

#include "filigree/client_error.h"
#include "unary_call.h"

namespace filigree {

std::uint32_t DetailSwitch::max_vertices() const {
  std::lock_guard lock(mutex_);
  return max_vertices_;
}

void DetailSwitch::opened() {
  std::lock_guard lock(mutex_);
  stream_known_ = false;
}

void DetailSwitch::observe(const v1::Frame& message) {
  if (!message.has_level()) return;
  std::lock_guard lock(mutex_);
  stream_id_ = message.level().stream_id();
  stream_known_ = true;
}

std::uint32_t DetailSwitch::set(v1::Filigree::Stub& stub, const std::string& session_id, const std::string& token,
                                Routing routing, std::chrono::milliseconds timeout, std::uint32_t max_vertices) {
  if (max_vertices == 0)
    throw ClientError(grpc::StatusCode::INVALID_ARGUMENT, "set_detail: a budget is at least 1 vertex");
  v1::SetDetailRequest request;
  request.set_session_id(session_id);
  request.set_max_vertices(max_vertices);
  {
    std::lock_guard lock(mutex_);
    if (max_vertices_ == 0)
      throw ClientError(grpc::StatusCode::FAILED_PRECONDITION,
                        "set_detail: the stream was opened at full detail (max_vertices 0); open it with a vertex "
                        "budget to change its level");
    if (!stream_known_)
      throw ClientError(grpc::StatusCode::FAILED_PRECONDITION,
                        "set_detail: the stream's level has not been read yet (it is the stream's first message)");
    request.set_stream_id(stream_id_);
  }
  const v1::SetDetailResponse response =
      unary_call(stub, &v1::Filigree::Stub::SetDetail, session_id, token, request, routing, timeout);
  std::lock_guard lock(mutex_);
  max_vertices_ = max_vertices;  // a reconnected stream asks for it
  return response.vertex_count();
}

}  // namespace filigree
