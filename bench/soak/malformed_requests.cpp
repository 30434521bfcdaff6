#include "bench/soak/malformed_requests.h"

#include <cmath>
#include <optional>
#include <random>

#include <grpcpp/generic/generic_stub.h>

#include "filigree/call_metadata.h"

namespace filigree::soak {

namespace {

using grpc::StatusCode;

constexpr auto kDeadline = std::chrono::seconds(60);

std::string random_hex(std::size_t digits) {
  std::random_device device;
  std::mt19937_64 random(device());
  const char* hex = "0123456789abcdef";
  std::string s;
  for (std::size_t i = 0; i < digits; ++i) s += hex[random() % 16];
  return s;
}

void prepare(grpc::ClientContext& context, const std::string& session_id, const std::string& token) {
  context.set_deadline(std::chrono::system_clock::now() + kDeadline);
  set_session_metadata(context, session_id, token);
}

// A Drive stream with one pose: the status its refusal names (Frame.refused:
// the stream goes on), else the stream's own once the server ends it.
grpc::Status drive_once(v1::Filigree::Stub& stub, const SessionHandle& s, const v1::DriveRequest& request) {
  grpc::ClientContext context;
  prepare(context, s.session_id, s.editor_token);
  auto stream = stub.Drive(&context);
  stream->Write(request);
  stream->WritesDone();
  v1::Frame frame;
  std::optional<grpc::Status> refused;
  while (stream->Read(&frame))  // a frame of another driver may come before the refusal
    if (frame.has_refused())
      refused = grpc::Status(static_cast<grpc::StatusCode>(frame.refused().code()), frame.refused().message());
  const grpc::Status ended = stream->Finish();
  if (refused && !ended.ok()) return {grpc::StatusCode::INTERNAL, "a refused pose ended the stream: " + ended.error_message()};
  return refused ? *refused : ended;
}

grpc::Status upload(v1::Filigree::Stub& stub, const std::vector<v1::CreateSessionRequest>& requests) {
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + kDeadline);
  auto stream = stub.CreateSession(&context);
  for (const auto& r : requests)
    if (!stream->Write(r)) break;
  stream->WritesDone();
  v1::CreateSessionResponse response;
  while (stream->Read(&response)) {
  }
  return stream->Finish();
}

v1::CreateSessionRequest begin(const std::string& format, std::size_t bytes) {
  v1::CreateSessionRequest r;
  r.mutable_begin()->set_format(format);
  r.mutable_begin()->set_total_bytes(bytes);
  r.mutable_begin()->set_client_name("soak-malformed");
  return r;
}

v1::CreateSessionRequest chunk(const std::string& bytes) {
  v1::CreateSessionRequest r;
  r.set_chunk(bytes);
  return r;
}

// Meshes that do not parse or do not make a mesh, in turn.
struct BadMesh {
  const char* format;
  std::string bytes;
};
const std::vector<BadMesh>& bad_meshes() {
  static const std::vector<BadMesh> meshes = {
      // A header promising more than the body has.
      {"ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
              "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0\n"},
      // A face naming a vertex that does not exist.
      {"obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n"},
      // Not a GLB beyond its magic.
      {"glb", std::string("glTF\x02\0\0\0\xff\xff\xff\x7f", 12) + std::string(64, '\x5a')},
  };
  return meshes;
}

struct Kind {
  const char* name;
  StatusCode expected;
};

// In the order send() takes them. Expected codes: filigree_service.cpp's
// authorize() (token missing; unknown session or wrong token, one answer; wrong role),
// Session::submit's PoseError → INVALID_ARGUMENT, CreateReactor's
// MeshIoError / InvalidMeshError / missing begin → INVALID_ARGUMENT.
const Kind kKinds[] = {
    {"wrong-size pose (Drive)", StatusCode::INVALID_ARGUMENT},
    {"NaN coordinate (SubmitPose)", StatusCode::INVALID_ARGUMENT},
    {"base index out of range (Drive, partial pose)", StatusCode::INVALID_ARGUMENT},
    {"wrong token (GetState)", StatusCode::NOT_FOUND},  // what an unknown id hears
    {"no token (JoinSession)", StatusCode::UNAUTHENTICATED},
    {"viewer token poses (SubmitPose)", StatusCode::PERMISSION_DENIED},
    {"unknown session (Watch)", StatusCode::NOT_FOUND},
    {"malformed mesh (CreateSession)", StatusCode::INVALID_ARGUMENT},
    {"upload without begin (CreateSession)", StatusCode::INVALID_ARGUMENT},
    // Bytes that are no GetStateRequest. GetState is a raw method (its answer
    // shares the frames' bytes): the service parses the request itself and
    // says what is wrong. (For a typed method gRPC's callback API answers
    // UNIMPLEMENTED with no message, CallbackUnaryHandler::RunHandler, 1.51.)
    {"corrupt request bytes (GetState)", StatusCode::INVALID_ARGUMENT},
};

}  // namespace

std::size_t MalformedRequests::kinds() { return std::size(kKinds); }

MalformedRequests::MalformedRequests(const std::string& address, const std::vector<const SessionHandle*>& sessions,
                                     std::chrono::milliseconds every, Failures& failures)
    : channel_(grpc::CreateChannel(address, grpc::InsecureChannelCredentials())),
      stub_(v1::Filigree::NewStub(channel_)), sessions_(sessions), every_(every), failures_(failures),
      bad_token_(random_hex(32)) {
  for (const Kind& k : kKinds) tallies_.push_back({k.name, k.expected, {}, 0});
}

MalformedRequests::~MalformedRequests() { stop(); }

void MalformedRequests::start() {
  thread_ = std::thread([this] { run(); });
}

void MalformedRequests::stop() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  stop_cv_.notify_all();
  if (thread_.joinable()) thread_.join();
}

std::vector<MalformedTally> MalformedRequests::tallies() const {
  std::lock_guard lock(mutex_);
  return tallies_;
}

void MalformedRequests::run() {
  auto next = std::chrono::steady_clock::now();
  for (std::size_t n = 0;; ++n) {
    const std::size_t kind = n % kinds();
    // Each kind meets every session in turn.
    const SessionHandle& session = *sessions_[(n / kinds()) % sessions_.size()];
    grpc::Status status;
    try {
      status = send(kind, session);
    } catch (const std::exception& e) {
      status = {StatusCode::UNKNOWN, std::string("the client threw: ") + e.what()};
    }
    const Kind& k = kKinds[kind];
    if (status.error_code() != k.expected)
      failures_.add(std::string("malformed request '") + k.name + "' on session " + session.session_id + " got " +
                    status_code_name(status.error_code()) + " (" + status.error_message() + "), expected " +
                    status_code_name(k.expected));
    std::unique_lock lock(mutex_);
    ++tallies_[kind].sent;
    ++tallies_[kind].got[status.error_code()];
    // The workload's pace; stop() only cuts the wait short.
    next += every_;
    if (stop_cv_.wait_until(lock, next, [&] { return stopping_; })) return;
  }
}

grpc::Status MalformedRequests::send(std::size_t kind, const SessionHandle& s) {
  const std::size_t m = s.mesh.base_vertex_count();
  // A pose of the session, made malformed by the case that uses it.
  const auto pose = [&] {
    v1::DriveRequest r;
    r.set_session_id(s.session_id);
    r.set_pose_id(1);
    r.set_client_name("soak-malformed");
    return r;
  };
  switch (kind) {
    case 0: {
      v1::DriveRequest r = pose();
      r.mutable_positions()->Assign(s.mesh.base_positions.begin(), s.mesh.base_positions.end() - 3);  // one vertex short
      return drive_once(*stub_, s, r);
    }
    case 1: {
      v1::DriveRequest r = pose();
      r.mutable_positions()->Assign(s.mesh.base_positions.begin(), s.mesh.base_positions.end());
      r.set_positions(static_cast<int>(m), std::nanf(""));  // every coordinate but one is fine
      grpc::ClientContext context;
      prepare(context, s.session_id, s.editor_token);
      v1::SubmitPoseResponse response;
      return stub_->SubmitPose(&context, r, &response);
    }
    case 2: {
      v1::DriveRequest r = pose();
      r.add_indices(static_cast<std::uint32_t>(m));  // one past the last base vertex
      for (int k = 0; k < 3; ++k) r.add_positions(0.0f);
      return drive_once(*stub_, s, r);
    }
    case 3: {
      grpc::ClientContext context;
      prepare(context, s.session_id, bad_token_);
      v1::GetStateRequest r;
      r.set_session_id(s.session_id);
      v1::SessionState state;
      return stub_->GetState(&context, r, &state);
    }
    case 4: {
      grpc::ClientContext context;
      prepare(context, s.session_id, "");
      v1::JoinSessionRequest r;
      r.set_session_id(s.session_id);
      v1::SessionInfo info;
      return stub_->JoinSession(&context, r, &info);
    }
    case 5: {
      v1::DriveRequest r = pose();  // well formed, but sent with the viewer token
      r.mutable_positions()->Assign(s.mesh.base_positions.begin(), s.mesh.base_positions.end());
      grpc::ClientContext context;
      prepare(context, s.session_id, s.viewer_token);
      v1::SubmitPoseResponse response;
      return stub_->SubmitPose(&context, r, &response);
    }
    case 6: {
      const std::string unknown = random_hex(20);
      grpc::ClientContext context;
      prepare(context, unknown, bad_token_);
      v1::WatchRequest r;
      r.set_session_id(unknown);
      r.set_frame_format(v1::FRAME_FORMAT_CHUNKED);
      auto stream = stub_->Watch(&context, r);
      v1::Frame frame;
      while (stream->Read(&frame)) {
      }
      return stream->Finish();
    }
    case 7: {
      const BadMesh& mesh = bad_meshes()[bad_mesh_turn_++ % bad_meshes().size()];
      return upload(*stub_, {begin(mesh.format, mesh.bytes.size()), chunk(mesh.bytes)});
    }
    case 8:
      return upload(*stub_, {chunk("v 0 0 0\n")});
    case 9: {
      // A length-delimited field 1 (session_id) claiming 2^28 bytes, with 3 present.
      const std::string garbage("\x0a\x80\x80\x80\x80\x01" "abc", 9);
      grpc::Slice slice(garbage);
      grpc::ByteBuffer request(&slice, 1), response;
      grpc::ClientContext context;
      prepare(context, s.session_id, s.viewer_token);
      grpc::GenericStub generic(channel_);
      std::mutex done_mutex;
      std::condition_variable done_cv;
      std::optional<grpc::Status> done;
      generic.UnaryCall(&context, "/filigree.v1.Filigree/GetState", grpc::StubOptions(), &request, &response,
                        [&](grpc::Status status) {
                          std::lock_guard lock(done_mutex);
                          done = std::move(status);
                          done_cv.notify_all();
                        });
      std::unique_lock lock(done_mutex);
      done_cv.wait(lock, [&] { return done.has_value(); });  // the call's deadline bounds this
      return *done;
    }
  }
  return {StatusCode::INTERNAL, "no such malformed request kind"};
}

}  // namespace filigree::soak
