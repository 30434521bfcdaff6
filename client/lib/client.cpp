#include "filigree/client.h"

#include <algorithm>
#include <optional>
#include <random>

#include "filigree/channel_arguments.h"
#include "pose_check.h"
#include "unary_call.h"

namespace filigree {
namespace {

constexpr std::size_t kChunkBytes = 1 << 19;  // upload chunk: under the smallest --max-message-mib (1)

// Unary calls are retried while a session moves between replicas (or a
// replica restarts): UNAVAILABLE, up to 5 attempts over about 3 s.
constexpr char kServiceConfig[] = R"({"methodConfig": [{
  "name": [{"service": "filigree.v1.Filigree", "method": "JoinSession"},
           {"service": "filigree.v1.Filigree", "method": "GetState"},
           {"service": "filigree.v1.Filigree", "method": "SetOptions"},
           {"service": "filigree.v1.Filigree", "method": "SubmitPose"},
           {"service": "filigree.v1.Filigree", "method": "LocateSession"}],
  "retryPolicy": {"maxAttempts": 5, "initialBackoff": "0.25s", "maxBackoff": "1.5s",
                  "backoffMultiplier": 2, "retryableStatusCodes": ["UNAVAILABLE"]}}]})";

std::shared_ptr<grpc::Channel> make_channel(const std::string& target,
                                            const std::shared_ptr<grpc::ChannelCredentials>& credentials) {
  grpc::ChannelArguments args = frame_channel_arguments();
  args.SetServiceConfigJSON(kServiceConfig);
  return grpc::CreateCustomChannel(target, credentials, args);
}

// 20 random lowercase hex digits: a new session's id, chosen here so that a
// load balancer routing by x-session-id sends the upload to its replica.
std::string new_session_id() {
  std::random_device device;
  static constexpr char kHex[] = "0123456789abcdef";
  std::string id;
  while (id.size() < 20) {
    std::uint32_t bits = device();
    for (int k = 0; k < 8 && id.size() < 20; ++k, bits >>= 4) id += kHex[bits & 15];
  }
  return id;
}

}  // namespace

Client::Client(const std::string& target) : Client(make_channel(target, grpc::InsecureChannelCredentials())) {}

Client::Client(const std::string& target, const std::shared_ptr<grpc::ChannelCredentials>& credentials)
    : Client(make_channel(target, credentials)) {}

Client::Client(std::shared_ptr<grpc::Channel> channel)
    : channel_(std::move(channel)), stub_(v1::Filigree::NewStub(channel_)) {}

SessionHandle Client::create_session(const std::string& mesh_bytes, const std::string& format,
                                     const v1::SessionOptions& options, const std::string& client_name,
                                     const ProgressCallback& progress) {
  grpc::ClientContext context;
  const std::string session_id = new_session_id();
  set_session_metadata(context, session_id, {});
  if (!api_key_.empty()) context.AddMetadata("x-filigree-api-key", api_key_);
  auto stream = stub_->CreateSession(&context);
  // If a progress callback throws, the call is cancelled and drained first:
  // gRPC wants Finish() before the stream goes away.
  struct FinishOnUnwind {
    grpc::ClientContext& context;
    grpc::ClientReaderWriter<v1::CreateSessionRequest, v1::CreateSessionResponse>& stream;
    bool finished = false;
    ~FinishOnUnwind() {
      if (finished) return;
      context.TryCancel();
      for (v1::CreateSessionResponse r; stream.Read(&r);) {
      }
      stream.Finish();
    }
  } guard{context, *stream};

  v1::CreateSessionRequest request;
  auto* begin = request.mutable_begin();
  begin->set_format(format);
  begin->set_total_bytes(mesh_bytes.size());
  *begin->mutable_options() = options;
  begin->set_client_name(client_name);
  begin->set_session_id(session_id);
  bool writing = stream->Write(request);
  // The server reads the whole file before it answers; a refusal (too large)
  // makes Write fail, and Finish below reports why.
  for (std::size_t at = 0; writing && at < mesh_bytes.size(); at += kChunkBytes) {
    const std::size_t n = std::min(kChunkBytes, mesh_bytes.size() - at);
    request.set_chunk(mesh_bytes.data() + at, n);
    writing = stream->Write(request);
    if (writing && progress) progress("uploading", double(at + n) / double(mesh_bytes.size()));
  }
  if (writing) stream->WritesDone();

  std::optional<v1::CreateSessionResponse::Created> created;
  v1::CreateSessionResponse response;
  while (stream->Read(&response)) {
    if (response.has_progress() && progress) progress(response.progress().stage(), response.progress().fraction());
    if (response.has_created()) created = std::move(*response.mutable_created());
  }
  guard.finished = true;
  throw_if_error(stream->Finish());
  if (!created) throw ClientError(grpc::StatusCode::DATA_LOSS, "the server ended the upload without creating a session");
  read_rest_in_parts(created->info().session_id(), created->editor_token(), *created->mutable_info());
  SessionMesh mesh = to_session_mesh(created->info());
  mesh.role = v1::ROLE_EDITOR;  // its creator holds the editor token
  return SessionHandle{created->info().session_id(), created->editor_token(), created->viewer_token(),
                       created->cached(), std::move(mesh)};
}

SessionMesh Client::join(const std::string& session_id, const std::string& token) {
  v1::JoinSessionRequest request;
  request.set_session_id(session_id);
  v1::SessionInfo info = unary_call(*stub_, &v1::Filigree::Stub::JoinSession, session_id, token, request, routing_, call_timeout_);
  read_rest_in_parts(session_id, token, info);
  return to_session_mesh(info);
}

void Client::read_rest_in_parts(const std::string& session_id, const std::string& token, v1::SessionInfo& info) {
  v1::RestMesh& rest = *info.mutable_rest();
  if (!rest.in_parts()) return;
  const std::uint64_t positions = 3ull * rest.vertex_count(), faces = 3ull * rest.face_count();
  rest.mutable_positions()->Reserve(static_cast<int>(positions));
  rest.mutable_faces()->Reserve(static_cast<int>(faces));
  grpc::ClientContext context;
  set_session_metadata(context, session_id, token, routing_);
  context.set_deadline(std::chrono::system_clock::now() + call_timeout_);
  v1::GetRestMeshRequest request;
  request.set_session_id(session_id);
  auto reader = stub_->GetRestMesh(&context, request);
  // Checked as parts arrive: a server sending more than the summary said
  // cannot make the client hold more than the mesh.
  bool overflow = false;
  for (v1::RestMeshPart part; !overflow && reader->Read(&part);) {
    overflow = rest.positions_size() + std::uint64_t(part.positions_size()) > positions ||
               rest.faces_size() + std::uint64_t(part.faces_size()) > faces ||
               rest.uploaded_ids_size() + std::uint64_t(part.uploaded_ids_size()) > rest.vertex_count();
    if (overflow) break;
    rest.mutable_positions()->Add(part.positions().begin(), part.positions().end());
    rest.mutable_faces()->Add(part.faces().begin(), part.faces().end());
    rest.mutable_uploaded_ids()->Add(part.uploaded_ids().begin(), part.uploaded_ids().end());
  }
  if (overflow) context.TryCancel();
  const grpc::Status status = reader->Finish();
  if (overflow)
    throw ClientError(grpc::StatusCode::DATA_LOSS, "the rest mesh's parts hold more than its " +
                                                       std::to_string(rest.vertex_count()) + " vertices and " +
                                                       std::to_string(rest.face_count()) + " faces");
  throw_if_error(status);
  if (std::uint64_t(rest.positions_size()) != positions || std::uint64_t(rest.faces_size()) != faces)
    throw ClientError(grpc::StatusCode::DATA_LOSS, "the rest mesh's parts hold " + std::to_string(rest.positions_size() / 3) +
                                                       " vertices and " + std::to_string(rest.faces_size() / 3) +
                                                       " faces, not " + std::to_string(rest.vertex_count()) + " and " +
                                                       std::to_string(rest.face_count()));
  rest.set_in_parts(false);
}

v1::SessionState Client::state(const std::string& session_id, const std::string& token) {
  v1::GetStateRequest request;
  request.set_session_id(session_id);
  request.set_frame_format(v1::FRAME_FORMAT_CHUNKED);
  return unary_call(*stub_, &v1::Filigree::Stub::GetState, session_id, token, request, routing_, call_timeout_);
}

void Client::set_threshold(const std::string& session_id, const std::string& token, double threshold,
                           bool whole_mesh, const std::string& client_name) {
  v1::SetOptionsRequest request;
  request.set_session_id(session_id);
  request.set_threshold(threshold);
  request.set_whole_mesh(whole_mesh);
  request.set_client_name(client_name);
  unary_call(*stub_, &v1::Filigree::Stub::SetOptions, session_id, token, request, routing_, call_timeout_);
}

std::uint32_t Client::set_handles(const std::string& session_id, const std::string& token,
                                  const std::string& client_name, std::span<const std::uint32_t> vertices,
                                  std::span<const std::array<float, 3>> targets, std::uint64_t gesture_id) {
  if (vertices.size() != targets.size())
    throw ClientError(grpc::StatusCode::INVALID_ARGUMENT, std::to_string(vertices.size()) + " handle vertices but " +
                                                              std::to_string(targets.size()) + " targets");
  v1::SetHandlesRequest request;
  request.set_session_id(session_id);
  request.set_client_name(client_name);
  request.set_gesture_id(gesture_id);
  for (std::size_t i = 0; i < vertices.size(); ++i) {
    v1::Handle* h = request.add_handles();
    h->set_vertex(vertices[i]);
    h->set_x(targets[i][0]);
    h->set_y(targets[i][1]);
    h->set_z(targets[i][2]);
  }
  return unary_call(*stub_, &v1::Filigree::Stub::SetHandles, session_id, token, request, routing_, call_timeout_).handles_in_session();
}

std::uint64_t Client::submit_pose(const std::string& session_id, const std::string& token,
                                  const std::string& client_name, std::span<const float> positions,
                                  std::uint64_t gesture_id) {
  check_positions("submit_pose", {}, positions);
  v1::DriveRequest request;
  request.set_session_id(session_id);
  request.set_client_name(client_name);
  request.set_gesture_id(gesture_id);
  request.mutable_positions()->Assign(positions.begin(), positions.end());
  return unary_call(*stub_, &v1::Filigree::Stub::SubmitPose, session_id, token, request, routing_, call_timeout_)
      .accepted_at_version();
}

void Client::close(const std::string& session_id, const std::string& token) {
  v1::CloseSessionRequest request;
  request.set_session_id(session_id);
  unary_call(*stub_, &v1::Filigree::Stub::CloseSession, session_id, token, request, routing_, call_timeout_);
}

std::vector<v1::ListSessionsResponse::Entry> Client::list() {
  grpc::ClientContext context;
  if (!api_key_.empty()) context.AddMetadata("x-filigree-api-key", api_key_);
  context.set_deadline(std::chrono::system_clock::now() + call_timeout_);
  v1::ListSessionsResponse response;
  throw_if_error(stub_->ListSessions(&context, v1::ListSessionsRequest(), &response));
  return {response.sessions().begin(), response.sessions().end()};
}

v1::SessionLocation Client::locate(const std::string& session_id, const std::string& token) {
  v1::LocateSessionRequest request;
  request.set_session_id(session_id);
  grpc::ClientContext context;
  set_session_metadata(context, session_id, token, routing_);
  if (!api_key_.empty()) context.AddMetadata("x-filigree-api-key", api_key_);
  context.set_deadline(std::chrono::system_clock::now() + call_timeout_);
  v1::SessionLocation response;
  throw_if_error(stub_->LocateSession(&context, request, &response));
  return response;
}

std::unique_ptr<Driver> Client::drive(const std::string& session_id, const std::string& token,
                                      const std::string& client_name, Reconnect reconnect) {
  return drive(session_id, token, client_name, DriveOptions{}, std::move(reconnect));
}

std::unique_ptr<Driver> Client::drive(const std::string& session_id, const std::string& token,
                                      const std::string& client_name, const DriveOptions& options,
                                      Reconnect reconnect) {
  return std::unique_ptr<Driver>(
      new Driver(*stub_, session_id, token, client_name, options, routing_, std::move(reconnect), call_timeout_));
}

std::unique_ptr<Watcher> Client::watch(const std::string& session_id, const std::string& token,
                                       std::uint64_t after_version, Reconnect reconnect) {
  return watch(session_id, token, WatchOptions{.after_version = after_version}, std::move(reconnect));
}

std::unique_ptr<Watcher> Client::watch(const std::string& session_id, const std::string& token,
                                       const WatchOptions& options, Reconnect reconnect) {
  return std::unique_ptr<Watcher>(
      new Watcher(*stub_, session_id, token, options, routing_, std::move(reconnect), call_timeout_));
}

std::unique_ptr<Watcher> Client::play_clip(const std::string& session_id, const std::string& token,
                                           const std::string& clip, const ClipPlayback& playback,
                                           const std::string& client_name) {
  v1::PlayClipRequest request;
  request.set_session_id(session_id);
  request.set_clip(clip);
  request.set_speed(playback.speed);
  request.set_loop(playback.loop);
  request.set_start_seconds(playback.start_seconds);
  request.set_max_rate(playback.max_rate);
  request.set_client_name(client_name);
  request.set_frame_format(v1::FRAME_FORMAT_CHUNKED);
  return std::unique_ptr<Watcher>(new Watcher(*stub_, request, token, routing_, call_timeout_));
}

}  // namespace filigree
