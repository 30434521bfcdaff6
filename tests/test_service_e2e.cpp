// filigree-server end to end, over gRPC on loopback, against the contract
// alone (generated stubs): upload, drive, watch, merge, auth, errors, limits,
// restart, the hierarchy cache.

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iomanip>
#include <fstream>
#include <sstream>
#include <thread>

#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "codec/delta_codec.h"
#include "codec/keyed_deltas.h"
#include "filigree/v1/filigree.grpc.pb.h"
#include "hierarchy/hierarchy.h"
#include "mesh/mesh_io.h"
#include "hierarchy/hierarchy_file.h"
#include "mesh/vertex_order.h"
#include "preprocess/preprocess.h"
#include "runtime/deformer.h"
#include "runtime/procedural_motion.h"
#include "support/forged_hierarchy.h"
#include "support/server_process.h"
#include "support/grpc_upload.h"
#include "support/test_meshes.h"

namespace filigree {
namespace {

using test::ServerProcess;

using test::file_bytes;

struct Created {
  grpc::Status status;
  v1::CreateSessionResponse::Created created;
  int progress_messages = 0;
};

class ServiceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    data_dir_ = std::filesystem::path(::testing::TempDir()) /
                ("filigree_e2e_" + std::to_string(::getpid()) + "_" + ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::remove_all(data_dir_);
    start({});
  }
  void TearDown() override {
    server_.reset();
    std::filesystem::remove_all(data_dir_);
  }
  void start(std::vector<std::string> extra) {
    extra.insert(extra.end(), {"--data-dir", data_dir_.string()});
    server_ = std::make_unique<ServerProcess>(FILIGREE_SERVER_BINARY, extra);
    channel_ = grpc::CreateChannel(server_->address(), grpc::InsecureChannelCredentials());
    stub_ = v1::Filigree::NewStub(channel_);
  }

  static std::unique_ptr<grpc::ClientContext> context(const std::string& session, const std::string& token) {
    auto c = std::make_unique<grpc::ClientContext>();
    if (!token.empty()) c->AddMetadata("x-filigree-token", token);
    if (!session.empty()) c->AddMetadata("x-session-id", session);
    return c;
  }

  Created upload(const std::string& bytes, const std::string& format, std::uint32_t base_vertices = 150) {
    Created out;
    grpc::ClientContext ctx;
    auto stream = stub_->CreateSession(&ctx);
    v1::CreateSessionRequest begin;
    begin.mutable_begin()->set_format(format);
    begin.mutable_begin()->set_total_bytes(bytes.size());
    begin.mutable_begin()->mutable_options()->set_base_vertices(base_vertices);
    begin.mutable_begin()->set_client_name("test");
    stream->Write(begin);
    // Small chunks so the upload really is streamed.
    for (std::size_t at = 0; at < bytes.size(); at += 16384) {
      v1::CreateSessionRequest chunk;
      chunk.set_chunk(bytes.substr(at, 16384));
      if (!stream->Write(chunk)) break;
    }
    stream->WritesDone();
    v1::CreateSessionResponse r;
    while (stream->Read(&r)) {
      if (r.has_progress()) ++out.progress_messages;
      if (r.has_created()) out.created = r.created();
    }
    out.status = stream->Finish();
    return out;
  }

  // Preprocesses bunny_small the way the server does, for local references.
  // Sessions order vertices along a space-filling curve (locality_order).
  static const Hierarchy& local_hierarchy() {
    static const Hierarchy h = [] {
      const TriMesh uploaded = test::shipped_mesh("bunny_small.obj");
      PreprocessOptions o;
      o.base_vertices = 150;
      return preprocess(permute_vertices(uploaded, locality_order(uploaded.positions)), o);
    }();
    return h;
  }

  // A watch of a session; cancelled and finished when it goes.
  struct Watching {
    std::unique_ptr<grpc::ClientContext> context;
    std::unique_ptr<grpc::ClientReader<v1::Frame>> reader;
    ~Watching() {
      context->TryCancel();
      reader->Finish();
    }
  };
  // Opens a watch of session `id` and reads its first frame (the current
  // one) into `first`; false if none came.
  std::unique_ptr<Watching> open_watch(const std::string& id, const std::string& token, v1::Frame& first) {
    auto w = std::make_unique<Watching>();
    w->context = context(id, token);
    v1::WatchRequest wr;
    wr.set_session_id(id);
    w->reader = stub_->Watch(w->context.get(), wr);
    EXPECT_TRUE(w->reader->Read(&first)) << "no current frame";
    return w;
  }

  // Drives one good pose (base vertex 3 moved) with id `pose_id` and expects
  // its frame, then a clean end of the stream.
  void expect_pose_answered(const std::string& id, const std::string& editor, std::uint64_t pose_id) {
    v1::DriveRequest good;
    good.set_session_id(id);
    good.set_pose_id(pose_id);
    good.add_indices(3);
    good.add_positions(0.1f), good.add_positions(0.2f), good.add_positions(0.3f);
    auto ctx = context(id, editor);
    auto drive = stub_->Drive(ctx.get());
    ASSERT_TRUE(drive->Write(good));
    v1::Frame f;
    do {
      ASSERT_TRUE(drive->Read(&f)) << "the stream ended before the frame of pose " << pose_id;
    } while (f.pose_id() != pose_id);
    drive->WritesDone();
    while (drive->Read(&f)) {
    }
    EXPECT_TRUE(drive->Finish().ok());
  }

  // Submits a pose that moves base vertex 2 to (x, 0.5, 0.5) and returns the
  // first frame a watcher sees after it (a step that fails is a test failure).
  v1::Frame frame_after_pose(const std::string& id, const std::string& editor, float x) {
    v1::Frame f;
    const auto watch = open_watch(id, editor, f);
    v1::DriveRequest pose;
    pose.set_session_id(id);
    pose.add_indices(2);
    pose.add_positions(x), pose.add_positions(0.5f), pose.add_positions(0.5f);
    v1::SubmitPoseResponse accepted;
    if (stub_->SubmitPose(context(id, editor).get(), pose, &accepted).ok()) {
      do {
        if (!watch->reader->Read(&f)) {
          ADD_FAILURE() << "the watch ended before the pose's frame";
          break;
        }
      } while (f.version() <= accepted.accepted_at_version());
    } else {
      ADD_FAILURE() << "SubmitPose failed";
    }
    return f;
  }

  static std::vector<float> pose_floats(const Pose& p) {
    std::vector<float> out;
    for (const Vec3& v : p.positions) out.insert(out.end(), {float(v.x()), float(v.y()), float(v.z())});
    return out;
  }

  static std::vector<Vec3> decode(const v1::Frame& f) {
    EncodedDeltas e;
    e.bytes = f.deltas();
    e.count = f.vertex_count();
    e.bits = f.quantization_bits();
    e.min = f.delta_min();
    e.range = f.delta_range();
    return decode_deltas(e);
  }

  std::filesystem::path data_dir_;
  std::unique_ptr<ServerProcess> server_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::Filigree::Stub> stub_;
};

const std::string kBunny = test::shipped_path("bunny_small.obj");

TEST_F(ServiceTest, DrivenFramesDecodeToTheLocalDeformation) {
  const Created c = upload(file_bytes(kBunny), "obj");
  ASSERT_TRUE(c.status.ok()) << c.status.error_message();
  EXPECT_GT(c.progress_messages, 0);
  EXPECT_FALSE(c.created.cached());
  const v1::SessionInfo& info = c.created.info();
  ASSERT_EQ(info.base().original_ids_size(), 150);
  ASSERT_EQ(info.rest().vertex_count(), 1839u);

  // The stated mapping leads back to the uploaded vertices.
  const TriMesh uploaded = test::shipped_mesh("bunny_small.obj");
  ASSERT_EQ(info.rest().uploaded_ids_size(), 1839);
  for (int i = 0; i < 1839; ++i) {
    const Vec3& p = uploaded.positions[info.rest().uploaded_ids(i)];
    for (int k = 0; k < 3; ++k) ASSERT_EQ(info.rest().positions(3 * i + k), static_cast<float>(p[k]));
  }
  const Hierarchy& h = local_hierarchy();
  ASSERT_EQ(std::vector<Index>(info.base().original_ids().begin(), info.base().original_ids().end()), h.base_vertices);
  const Pose pose = procedural_pose(h.base_mesh().positions, Motion::kBend, 1.0);
  // The server receives float32 positions: deform the same rounded pose here.
  Pose rounded = pose;
  for (Vec3& v : rounded.positions) v = v.cast<float>().cast<double>();
  Deformer local(h);
  const std::vector<Vec3> expected = local.deform(rounded).positions;

  auto ctx = context(info.session_id(), c.created.editor_token());
  auto drive = stub_->Drive(ctx.get());
  v1::DriveRequest req;
  req.set_session_id(info.session_id());
  req.set_pose_id(7);
  req.set_client_name("engine");
  for (float x : pose_floats(pose)) req.add_positions(x);
  ASSERT_TRUE(drive->Write(req));
  v1::Frame frame;
  do {
    ASSERT_TRUE(drive->Read(&frame));
  } while (frame.pose_id() != 7);
  drive->WritesDone();
  while (drive->Read(&frame)) {
  }
  ASSERT_TRUE(drive->Finish().ok());

  EXPECT_GE(frame.version(), 1u);
  ASSERT_EQ(frame.changes_size(), 1);
  EXPECT_EQ(frame.changes(0).client_name(), "engine");
  const std::vector<Vec3> deltas = decode(frame);
  ASSERT_EQ(deltas.size(), expected.size());
  double worst = 0.0;
  for (std::size_t i = 0; i < deltas.size(); ++i) {
    const Vec3 rest(info.rest().positions(3 * i), info.rest().positions(3 * i + 1), info.rest().positions(3 * i + 2));
    worst = std::max(worst, (rest + deltas[i] - expected[i]).cwiseAbs().maxCoeff());
  }
  // Quantization error, plus float32 rounding of rest positions and deltas.
  EXPECT_LE(worst, frame.max_error() + 1e-5 * bounding_box_diagonal(h.rest_positions)) << "max_error " << frame.max_error();
  EXPECT_GT(frame.max_error(), 0.0f);
}

TEST_F(ServiceTest, TwoPartialDriversThreeWatchersOneOfThemStalled) {
  const Created c = upload(file_bytes(kBunny), "obj");
  ASSERT_TRUE(c.status.ok()) << c.status.error_message();
  const std::string id = c.created.info().session_id(), editor = c.created.editor_token(), viewer = c.created.viewer_token();
  const std::size_t m = 150;

  std::vector<std::unique_ptr<grpc::ClientContext>> contexts;
  std::vector<std::unique_ptr<grpc::ClientReader<v1::Frame>>> watchers;
  for (int w = 0; w < 3; ++w) {
    contexts.push_back(context(id, viewer));
    v1::WatchRequest wr;
    wr.set_session_id(id);
    watchers.push_back(stub_->Watch(contexts.back().get(), wr));
  }
  // Every watcher gets the current (rest) frame first.
  for (auto& w : watchers) {
    v1::Frame f;
    ASSERT_TRUE(w->Read(&f));
    EXPECT_EQ(f.version(), 0u);
  }

  // Driver A moves the first half of the base vertices, B the second half.
  const Pose rest = procedural_pose(local_hierarchy().base_mesh().positions, Motion::kBend, 0.0);
  auto ctx_a = context(id, editor), ctx_b = context(id, editor);
  auto a = stub_->Drive(ctx_a.get());
  auto b = stub_->Drive(ctx_b.get());
  const int kPoses = 20;
  std::vector<float> expected = pose_floats(rest);
  for (int p = 1; p <= kPoses; ++p) {
    struct Part {
      grpc::ClientReaderWriter<v1::DriveRequest, v1::Frame>* drv;
      const char* name;
      std::size_t lo, hi;
    };
    for (const Part& part : {Part{a.get(), "alice", 0, m / 2}, Part{b.get(), "bob", m / 2, m}}) {
      auto* drv = part.drv;
      const char* name = part.name;
      const std::size_t lo = part.lo, hi = part.hi;
      v1::DriveRequest r;
      r.set_session_id(id);
      r.set_pose_id(p);
      r.set_client_name(name);
      for (std::size_t v = lo; v < hi; ++v) {
        r.add_indices(static_cast<std::uint32_t>(v));
        const float offset = 0.01f * p * (name[0] == 'a' ? 1.0f : -1.0f);
        for (int k = 0; k < 3; ++k) {
          const float x = static_cast<float>(rest.positions[v][k]) + (k == 1 ? offset : 0.0f);
          r.add_positions(x);
          expected[3 * v + k] = x;
        }
      }
      ASSERT_TRUE(drv->Write(r));
    }
  }
  // Each driver reads until its last pose is answered.
  for (auto* drv : {a.get(), b.get()}) {
    v1::Frame f;
    do {
      ASSERT_TRUE(drv->Read(&f));
    } while (f.pose_id() != kPoses);
    drv->WritesDone();
    while (drv->Read(&f)) {
    }
    ASSERT_TRUE(drv->Finish().ok());
  }

  // The merged pose: newest write per base vertex, from both drivers.
  v1::SessionState state;
  auto sctx = context(id, viewer);
  v1::GetStateRequest gr;
  gr.set_session_id(id);
  ASSERT_TRUE(stub_->GetState(sctx.get(), gr, &state).ok());
  ASSERT_EQ(state.pose_size(), static_cast<int>(3 * m));
  for (std::size_t i = 0; i < 3 * m; ++i) ASSERT_EQ(state.pose(static_cast<int>(i)), expected[i]) << i;
  const std::uint64_t final_version = state.version();
  ASSERT_GE(final_version, 1u);

  // Watchers 0 and 1 read on and reach the final version with strictly
  // increasing versions, while watcher 2 has not read anything since the rest frame.
  for (int w = 0; w < 2; ++w) {
    v1::Frame f;
    std::uint64_t last = 0;
    do {
      ASSERT_TRUE(watchers[w]->Read(&f));
      EXPECT_GT(f.version(), last);
      last = f.version();
    } while (f.version() < final_version);
    EXPECT_EQ(f.version(), final_version);
  }
  // The stalled watcher resumes: it skips (mailbox of one) and gets the newest.
  {
    v1::Frame f;
    std::uint64_t last = 0;
    int reads = 0;
    do {
      ASSERT_TRUE(watchers[2]->Read(&f));
      EXPECT_GT(f.version(), last);
      last = f.version();
      ++reads;
    } while (f.version() < final_version);
    EXPECT_EQ(f.version(), final_version);
  }
  for (auto& c2 : contexts) c2->TryCancel();
  for (auto& w : watchers) w->Finish();

  // The frame names who changed what.
  bool saw_alice = false, saw_bob = false;
  for (const auto& ch : state.frame().changes()) {
    saw_alice |= ch.client_name() == "alice";
    saw_bob |= ch.client_name() == "bob";
  }
  EXPECT_TRUE(saw_alice || saw_bob);

  // A late joiner gets the current state at once.
  auto late_ctx = context(id, viewer);
  v1::WatchRequest wr;
  wr.set_session_id(id);
  auto late = stub_->Watch(late_ctx.get(), wr);
  v1::Frame f;
  ASSERT_TRUE(late->Read(&f));
  EXPECT_EQ(f.version(), final_version);
  late_ctx->TryCancel();
  late->Finish();
}

TEST_F(ServiceTest, TokensAreChecked) {
  const Created c = upload(file_bytes(kBunny), "obj");
  ASSERT_TRUE(c.status.ok());
  const std::string id = c.created.info().session_id();
  v1::JoinSessionRequest jr;
  jr.set_session_id(id);
  v1::SessionInfo info;
  EXPECT_EQ(stub_->JoinSession(context(id, "").get(), jr, &info).error_code(), grpc::StatusCode::UNAUTHENTICATED);
  // A wrong token hears what an unknown id hears, word for word but the id.
  const grpc::Status wrong = stub_->JoinSession(context(id, "not-a-token").get(), jr, &info);
  EXPECT_EQ(wrong.error_code(), grpc::StatusCode::NOT_FOUND);
  v1::JoinSessionRequest unknown_request;
  unknown_request.set_session_id("0123456789abcdef0123");
  const grpc::Status unknown = stub_->JoinSession(context("", "not-a-token").get(), unknown_request, &info);
  EXPECT_EQ(unknown.error_code(), grpc::StatusCode::NOT_FOUND);
  std::string said = wrong.error_message();
  said.replace(said.find(id), id.size(), "0123456789abcdef0123");
  EXPECT_EQ(said, unknown.error_message());
  EXPECT_TRUE(stub_->JoinSession(context(id, c.created.viewer_token()).get(), jr, &info).ok());
  EXPECT_EQ(info.base().original_ids_size(), 150);
  EXPECT_EQ(info.role(), v1::ROLE_VIEWER);  // what the page may show
  v1::SessionInfo as_editor;
  EXPECT_TRUE(stub_->JoinSession(context(id, c.created.editor_token()).get(), jr, &as_editor).ok());
  EXPECT_EQ(as_editor.role(), v1::ROLE_EDITOR);
  EXPECT_EQ(as_editor.base().original_ids_size(), 150);

  // A viewer may not drive.
  auto ctx = context(id, c.created.viewer_token());
  auto drive = stub_->Drive(ctx.get());
  v1::DriveRequest r;
  r.set_session_id(id);
  drive->Write(r);
  drive->WritesDone();
  v1::Frame f;
  while (drive->Read(&f)) {
  }
  EXPECT_EQ(drive->Finish().error_code(), grpc::StatusCode::PERMISSION_DENIED);

  v1::CloseSessionRequest cr;
  cr.set_session_id(id);
  v1::CloseSessionResponse close_response;
  EXPECT_EQ(stub_->CloseSession(context(id, c.created.viewer_token()).get(), cr, &close_response).error_code(),
            grpc::StatusCode::PERMISSION_DENIED);
}

TEST_F(ServiceTest, MalformedPosesAreRejectedAndTheSessionKeepsWorking) {
  const Created c = upload(file_bytes(kBunny), "obj");
  ASSERT_TRUE(c.status.ok());
  const std::string id = c.created.info().session_id(), editor = c.created.editor_token();
  // A bad pose is refused as that pose (Frame.refused naming it), not by
  // ending the stream: the same stream's next good pose gets its frame.
  auto try_pose = [&](v1::DriveRequest bad, std::uint64_t pose_id) {
    auto ctx = context(id, editor);
    auto drive = stub_->Drive(ctx.get());
    bad.set_session_id(id);
    bad.set_pose_id(pose_id);
    EXPECT_TRUE(drive->Write(bad));
    v1::DriveRequest good;
    good.set_pose_id(pose_id + 1);
    good.add_indices(3);
    good.add_positions(0.1f), good.add_positions(0.2f), good.add_positions(0.3f);
    EXPECT_TRUE(drive->Write(good));
    drive->WritesDone();
    v1::Frame f;
    std::string refused;
    std::uint64_t answered = 0;
    while (drive->Read(&f)) {
      if (f.has_refused()) {
        EXPECT_EQ(f.pose_id(), pose_id);
        EXPECT_EQ(f.refused().code(), static_cast<std::uint32_t>(grpc::StatusCode::INVALID_ARGUMENT));
        refused = f.refused().message();
      } else {
        answered = std::max(answered, f.pose_id());
      }
    }
    EXPECT_TRUE(drive->Finish().ok());
    EXPECT_EQ(answered, pose_id + 1) << "the good pose after the bad one was not answered";
    return refused;
  };
  v1::DriveRequest short_pose;
  for (int i = 0; i < 30; ++i) short_pose.add_positions(0.0f);
  const std::string short_refusal = try_pose(short_pose, 1);
  EXPECT_NE(short_refusal.find("30 coordinates"), std::string::npos) << short_refusal;

  v1::DriveRequest bad_index;
  bad_index.add_indices(150);
  bad_index.add_positions(0.0f), bad_index.add_positions(0.0f), bad_index.add_positions(0.0f);
  EXPECT_NE(try_pose(bad_index, 10).find("out of range"), std::string::npos);

  v1::DriveRequest nan_pose;
  nan_pose.add_indices(3);
  nan_pose.add_positions(std::nanf("")), nan_pose.add_positions(0.0f), nan_pose.add_positions(0.0f);
  EXPECT_NE(try_pose(nan_pose, 20).find("not finite"), std::string::npos);

  expect_pose_answered(id, editor, 42);  // a good pose still gets its frame
}

// The frame streams are raw methods (the server parses their requests
// itself), and so are JoinSession, SetOptions, GetState and GetOverlays: bytes that are no request
// message are refused as such, and the session keeps answering good poses.
TEST_F(ServiceTest, StreamRequestsThatAreNotMessagesAreRefused) {
  const Created c = upload(file_bytes(kBunny), "obj");
  ASSERT_TRUE(c.status.ok());
  const std::string id = c.created.info().session_id(), editor = c.created.editor_token();
  // One raw request on a streaming method, then half-close; how the call ended.
  const auto call_with_bytes = [&](const std::string& method, const std::string& bytes) {
    grpc::GenericStub generic(channel_);
    grpc::CompletionQueue cq;
    auto ctx = context(id, editor);
    auto call = generic.PrepareCall(ctx.get(), method, &cq);
    void* tag = nullptr;
    bool ok = false;
    call->StartCall(nullptr);
    EXPECT_TRUE(cq.Next(&tag, &ok));
    const grpc::Slice slice(bytes);
    call->Write(grpc::ByteBuffer(&slice, 1), nullptr);
    EXPECT_TRUE(cq.Next(&tag, &ok));
    call->WritesDone(nullptr);
    EXPECT_TRUE(cq.Next(&tag, &ok));
    for (grpc::ByteBuffer frame; ok;) {  // no frame is expected; read to the end
      call->Read(&frame, nullptr);
      EXPECT_TRUE(cq.Next(&tag, &ok));
    }
    grpc::Status status;
    call->Finish(&status, nullptr);
    EXPECT_TRUE(cq.Next(&tag, &ok));
    cq.Shutdown();
    while (cq.Next(&tag, &ok)) {
    }
    return status;
  };
  const std::string garbage("\xff\xff\xff\xff\xff\xff\xff\xff\xff\xff\xff", 11);  // a tag whose varint never ends
  for (const auto& [method, type] : {std::pair<std::string, std::string>{"Drive", "filigree.v1.DriveRequest"},
                                     {"Watch", "filigree.v1.WatchRequest"},
                                     {"PlayClip", "filigree.v1.PlayClipRequest"},
                                     {"JoinSession", "filigree.v1.JoinSessionRequest"},
                                     {"SetOptions", "filigree.v1.SetOptionsRequest"},
                                     {"GetState", "filigree.v1.GetStateRequest"},
                                     {"GetOverlays", "filigree.v1.GetOverlaysRequest"}}) {
    const grpc::Status status = call_with_bytes("/filigree.v1.Filigree/" + method, garbage);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << method << ": " << status.error_message();
    EXPECT_NE(status.error_message().find("not a valid " + type), std::string::npos) << status.error_message();
  }

  expect_pose_answered(id, editor, 7);
}

// While a mesh simplifies for seconds, its progress says how long is left
// (estimated from the recent rate: never before half a second).
TEST_F(ServiceTest, UploadProgressSaysTheTimeLeftWhileSimplifying) {
  const TriMesh sphere = test::icosphere(7);  // 163,842 vertices: seconds of simplification
  std::ostringstream off;
  off << std::setprecision(17) << "OFF\n" << sphere.positions.size() << ' ' << sphere.faces.size() << " 0\n";
  for (const Vec3& p : sphere.positions) off << p.x() << ' ' << p.y() << ' ' << p.z() << '\n';
  for (const Triangle& f : sphere.faces) off << "3 " << f[0] << ' ' << f[1] << ' ' << f[2] << '\n';
  grpc::ChannelArguments unbounded;  // its SessionInfo is over gRPC's default 4 MiB
  unbounded.SetMaxReceiveMessageSize(-1);
  const auto stub = v1::Filigree::NewStub(
      grpc::CreateCustomChannel(server_->address(), grpc::InsecureChannelCredentials(), unbounded));
  const test::Uploaded made = test::upload_mesh(*stub, off.str(), "off", 2000);
  ASSERT_TRUE(made.status.ok()) << made.status.error_message();
  std::size_t estimated = 0;
  for (const auto& p : made.progress) {
    EXPECT_GE(p.seconds_left(), 0.0);
    if (p.stage() != "simplifying") {
      EXPECT_EQ(p.seconds_left(), 0.0) << p.stage();
    }
    if (p.seconds_left() > 0.0) ++estimated;
  }
  EXPECT_GT(estimated, 0u) << made.progress.size() << " progress messages, none with a time left";
}

TEST_F(ServiceTest, UnknownSessionIsNotFound) {
  v1::GetStateRequest r;
  r.set_session_id("0123456789abcdef0123");
  v1::SessionState s;
  const grpc::Status status = stub_->GetState(context("", "some-token").get(), r, &s);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_NE(status.error_message().find("0123456789abcdef0123"), std::string::npos);
}

TEST_F(ServiceTest, BadAndOversizedMeshesAreRefused) {
  const Created garbage = upload("this is not an obj file\nf 1 2 9\n", "obj");
  EXPECT_EQ(garbage.status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  const Created nan = upload("v 0 0 0\nv 1 0 0\nv nan 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\nf 1 4 2\nf 2 4 3\n", "obj");
  EXPECT_EQ(nan.status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(nan.status.error_message().find("NaN"), std::string::npos) << nan.status.error_message();

  server_->terminate();
  start({"--max-mesh-bytes", "1000"});
  const Created big = upload(file_bytes(kBunny), "obj");
  EXPECT_EQ(big.status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_NE(big.status.error_message().find("--max-mesh-bytes"), std::string::npos);
}

TEST_F(ServiceTest, SameMeshTwiceIsPreprocessedOnce) {
  const Created first = upload(file_bytes(kBunny), "obj");
  const Created second = upload(file_bytes(kBunny), "obj");
  ASSERT_TRUE(first.status.ok() && second.status.ok());
  EXPECT_FALSE(first.created.cached());
  EXPECT_TRUE(second.created.cached());
  EXPECT_NE(first.created.info().session_id(), second.created.info().session_id());
  EXPECT_EQ(first.created.info().mesh_hash(), second.created.info().mesh_hash());
  std::size_t files = 0;
  for (const auto& e : std::filesystem::directory_iterator(data_dir_ / "hierarchies")) files += e.path().extension() == ".fgh";
  EXPECT_EQ(files, 1u);
}

TEST_F(ServiceTest, SessionsSurviveARestart) {
  const Created c = upload(file_bytes(kBunny), "obj");
  ASSERT_TRUE(c.status.ok());
  const std::string id = c.created.info().session_id(), editor = c.created.editor_token();
  {
    auto ctx = context(id, editor);
    auto drive = stub_->Drive(ctx.get());
    v1::DriveRequest r;
    r.set_session_id(id);
    r.set_pose_id(5);
    r.add_indices(10);
    r.add_positions(1.5f), r.add_positions(-2.0f), r.add_positions(0.25f);
    ASSERT_TRUE(drive->Write(r));
    v1::Frame f;
    do {
      ASSERT_TRUE(drive->Read(&f));
    } while (f.pose_id() != 5);
    drive->WritesDone();
    while (drive->Read(&f)) {
    }
    ASSERT_TRUE(drive->Finish().ok());
  }
  v1::SessionState before;
  v1::GetStateRequest gr;
  gr.set_session_id(id);
  ASSERT_TRUE(stub_->GetState(context(id, editor).get(), gr, &before).ok());
  ASSERT_GE(before.version(), 1u);

  EXPECT_EQ(server_->terminate(), 0) << "SIGTERM must drain and exit 0";
  start({});
  v1::SessionState after;
  ASSERT_TRUE(stub_->GetState(context(id, editor).get(), gr, &after).ok());
  EXPECT_EQ(after.version(), before.version());
  ASSERT_EQ(after.pose_size(), before.pose_size());
  for (int i = 0; i < after.pose_size(); ++i) ASSERT_EQ(after.pose(i), before.pose(i));
  EXPECT_EQ(after.pose(30), 1.5f);
  EXPECT_EQ(after.frame().version(), before.version());
  EXPECT_EQ(after.frame().deltas(), before.frame().deltas());
}

}  // namespace
}  // namespace filigree

namespace filigree {
namespace {

// Handles (every client's) and the adaptive cut survive a restart: two
// sessions of one mesh get the same history; one takes its next steps before
// the restart, the other after it, and they must agree. Each step waits for
// its frame, so both sessions compute the same frames (no coalescing).
TEST_F(ServiceTest, HandlesAndTheCutSurviveARestart) {
  const Created a = upload(file_bytes(kBunny), "obj"), b = upload(file_bytes(kBunny), "obj");
  ASSERT_TRUE(a.status.ok() && b.status.ok());
  const v1::RestMesh& rest = a.created.info().rest();
  struct Step {
    v1::Frame frame;
    std::uint32_t handles_in_session = 0;
  };
  auto watch_after = [&](const Created& c, std::uint64_t after) {
    const std::string& id = c.created.info().session_id();
    auto wctx = context(id, c.created.viewer_token());
    v1::WatchRequest wr;
    wr.set_session_id(id);
    wr.set_after_version(after);
    auto watch = stub_->Watch(wctx.get(), wr);
    v1::Frame f;
    bool read = false;
    while ((read = watch->Read(&f)) && f.version() <= after) {
    }
    EXPECT_TRUE(read) << "the watch ended before a frame after version " << after;
    wctx->TryCancel();
    watch->Finish();
    return f;
  };
  auto version_of = [&](const Created& c) {
    v1::SessionState state;
    v1::GetStateRequest gr;
    gr.set_session_id(c.created.info().session_id());
    EXPECT_TRUE(stub_->GetState(context(gr.session_id(), c.created.editor_token()).get(), gr, &state).ok());
    return state.version();
  };
  auto set_handles = [&](const Created& c, const std::string& client, int vertex, const Vec3& offset) {
    v1::SetHandlesRequest r;
    r.set_session_id(c.created.info().session_id());
    r.set_client_name(client);
    v1::Handle& h = *r.add_handles();
    h.set_vertex(vertex);
    h.set_x(rest.positions(3 * vertex) + float(offset.x()));
    h.set_y(rest.positions(3 * vertex + 1) + float(offset.y()));
    h.set_z(rest.positions(3 * vertex + 2) + float(offset.z()));
    v1::SetHandlesResponse response;
    EXPECT_TRUE(stub_->SetHandles(context(r.session_id(), c.created.editor_token()).get(), r, &response).ok());
    return Step{watch_after(c, response.accepted_at_version()), response.handles_in_session()};
  };
  auto bend = [&](const Created& c, double phase) {
    const Pose p = procedural_pose(local_hierarchy().base_mesh().positions, Motion::kBend, phase);
    v1::DriveRequest r;
    r.set_session_id(c.created.info().session_id());
    r.set_client_name("engine");
    for (float x : pose_floats(p)) r.add_positions(x);
    v1::SubmitPoseResponse accepted;
    EXPECT_TRUE(stub_->SubmitPose(context(r.session_id(), c.created.editor_token()).get(), r, &accepted).ok());
    return Step{watch_after(c, accepted.accepted_at_version()), 0};
  };
  auto overlays = [&](const Created& c) {
    v1::GetOverlaysRequest req;
    req.set_session_id(c.created.info().session_id());
    v1::Overlays o;
    EXPECT_TRUE(stub_->GetOverlays(context(req.session_id(), c.created.viewer_token()).get(), req, &o).ok());
    return o;
  };
  // The history: an adaptive cut (T > 0), Alice's and Bob's handles, bends.
  auto history = [&](const Created& c) {
    v1::SetOptionsRequest so;
    so.set_session_id(c.created.info().session_id());
    so.set_threshold(1e5);
    v1::SessionInfo info;
    ASSERT_TRUE(stub_->SetOptions(context(so.session_id(), c.created.editor_token()).get(), so, &info).ok());
    watch_after(c, info.version());
    EXPECT_EQ(set_handles(c, "alice", 100, Vec3(0.0, 0.3, 0.0)).handles_in_session, 1u);
    EXPECT_EQ(set_handles(c, "bob", 1500, Vec3(0.0, 0.0, 0.0)).handles_in_session, 2u);
    for (int i = 1; i <= 4; ++i) bend(c, 0.2 * i);
  };
  // The steps compared: overlays asked for (a frame of the current pose
  // follows, with them), a new pose, then Bob moves his handle (solved with
  // Alice's, which only a restored session still has).
  struct Steps {
    Step pose, handles;
    v1::Overlays overlays;
  };
  auto steps = [&](const Created& c) {
    Steps out;
    const std::uint64_t now = version_of(c);
    overlays(c);  // the first answer may not be ready: it starts a frame that builds them
    watch_after(c, now);
    out.pose = bend(c, 1.3);
    out.handles = set_handles(c, "bob", 1500, Vec3(0.1, -0.05, 0.0));
    out.overlays = overlays(c);
    return out;
  };
  history(a);
  history(b);
  const Steps before = steps(a);
  ASSERT_EQ(before.handles.handles_in_session, 2u);
  ASSERT_TRUE(before.overlays.ready());
  ASSERT_EQ(before.overlays.version(), before.handles.frame.version());
  ASSERT_GT(before.overlays.region_count(), 0u) << "T must have moved nodes into regions";
  const std::uint64_t b_version = version_of(b);

  EXPECT_EQ(server_->terminate(), 0);
  start({});
  EXPECT_EQ(version_of(b), b_version);
  const Steps after = steps(b);

  // Alice's handle is still there: Bob's replacement leaves two.
  EXPECT_EQ(after.handles.handles_in_session, 2u);
  // The same cut: overlays and the frames' cut statistics agree exactly.
  ASSERT_TRUE(after.overlays.ready());
  EXPECT_EQ(after.overlays.version(), after.handles.frame.version());
  EXPECT_EQ(after.overlays.region_count(), before.overlays.region_count());
  EXPECT_TRUE(std::equal(after.overlays.region_of().begin(), after.overlays.region_of().end(),
                         before.overlays.region_of().begin(), before.overlays.region_of().end()));
  EXPECT_TRUE(std::equal(after.overlays.cut_faces().begin(), after.overlays.cut_faces().end(),
                         before.overlays.cut_faces().begin(), before.overlays.cut_faces().end()));
  // The same frames, within both frames' stated quantization error (and
  // float32 rounding of rest positions and deltas).
  const double slack = 1e-6 * bounding_box_diagonal(local_hierarchy().rest_positions);
  for (const auto& [got, want] : {std::pair{&after.pose.frame, &before.pose.frame}, {&after.handles.frame, &before.handles.frame}}) {
    EXPECT_EQ(got->stats().cut_nodes(), want->stats().cut_nodes());
    EXPECT_EQ(got->stats().regions(), want->stats().regions());
    EXPECT_EQ(got->stats().region_vertices(), want->stats().region_vertices());
    const std::vector<Vec3> g = decode(*got), w = decode(*want);
    ASSERT_EQ(g.size(), w.size());
    double worst = 0.0;
    for (std::size_t i = 0; i < g.size(); ++i) worst = std::max(worst, (g[i] - w[i]).cwiseAbs().maxCoeff());
    EXPECT_LE(worst, double{got->max_error()} + want->max_error() + slack) << "frame " << got->version();
  }
}

// The first finite T of a mesh derives its node graph off gRPC's threads
// (SetOptions answers from a thread of its own): two sessions of one mesh
// asking at once both get it, each answer says so, and the second session's
// next frame is computed at its T.
TEST_F(ServiceTest, TwoSessionsOfOneMeshSetAFiniteTAtOnce) {
  const Created a = upload(file_bytes(kBunny), "obj"), b = upload(file_bytes(kBunny), "obj");
  ASSERT_TRUE(a.status.ok());
  ASSERT_TRUE(b.status.ok());
  struct Answer {
    grpc::Status status;
    v1::SessionInfo info;
  };
  Answer answers[2];
  std::vector<std::thread> callers;
  for (int i = 0; i < 2; ++i)
    callers.emplace_back([&, i] {
      const Created& c = i == 0 ? a : b;
      v1::SetOptionsRequest so;
      so.set_session_id(c.created.info().session_id());
      so.set_threshold(i == 0 ? 2e4 : 3e4);
      answers[i].status = stub_->SetOptions(context(so.session_id(), c.created.editor_token()).get(), so, &answers[i].info);
    });
  for (auto& t : callers) t.join();
  for (int i = 0; i < 2; ++i) {
    ASSERT_TRUE(answers[i].status.ok()) << answers[i].status.error_message();
    EXPECT_EQ(answers[i].info.options().threshold(), i == 0 ? 2e4 : 3e4);
  }
  // A pose of b: its frame is computed at b's T.
  EXPECT_EQ(frame_after_pose(b.created.info().session_id(), b.created.editor_token(), 0.5f).stats().threshold(), 3e4);
}

// Whole-mesh optimisation's factorisation is made before SetOptions answers
// (on its thread, not a frame worker; every session of the mesh shares it):
// the frame that first runs at T = ∞ makes no factorisation of its own.
TEST_F(ServiceTest, WholeMeshIsFactorisedBeforeItsFirstFrame) {
  const Created c = upload(file_bytes(kBunny), "obj");
  ASSERT_TRUE(c.status.ok());
  const std::string id = c.created.info().session_id(), editor = c.created.editor_token();
  v1::Frame f;  // the current frame, at T = 0
  const auto watch = open_watch(id, editor, f);
  v1::SetOptionsRequest so;
  so.set_session_id(id);
  so.set_whole_mesh(true);
  v1::SessionInfo info;
  ASSERT_TRUE(stub_->SetOptions(context(id, editor).get(), so, &info).ok());
  EXPECT_TRUE(info.options().whole_mesh());
  do {
    ASSERT_TRUE(watch->reader->Read(&f));
  } while (!std::isinf(f.stats().threshold()));
  EXPECT_GE(f.stats().largest_region(), 1024u);  // RegionSolver::kSharedMin: a shared factor
  EXPECT_EQ(f.stats().factorizations(), 0u);
  EXPECT_TRUE(f.stats().cut_converged());  // T = ∞ never moves its cut
}

// A cached hierarchy replaced by one that loads but whose removals do not
// delete their fans (what loading leaves to the first finite T, checked by
// the node graph): a session recorded at a finite T comes back at T = 0,
// asking for a finite T again is refused with what is wrong, and the session
// keeps computing frames.
TEST_F(ServiceTest, AHierarchyThatCannotRunAFiniteTIsRefusedAndTheSessionKeepsWorking) {
  const Created c = upload(file_bytes(kBunny), "obj");
  ASSERT_TRUE(c.status.ok());
  const std::string id = c.created.info().session_id(), editor = c.created.editor_token();
  v1::SetOptionsRequest so;
  so.set_session_id(id);
  so.set_threshold(2e4);
  v1::SessionInfo info;
  ASSERT_TRUE(stub_->SetOptions(context(id, editor).get(), so, &info).ok());
  EXPECT_EQ(info.options().threshold(), 2e4);
  ASSERT_EQ(server_->terminate(), 0);

  // Re-triangulate a hole across its other diagonal; the file's checksum is
  // written anew, so only the node graph can tell.
  std::filesystem::path file;
  for (const auto& e : std::filesystem::directory_iterator(data_dir_ / "hierarchies"))
    if (e.path().extension() == ".fgh") file = e.path();
  ASSERT_FALSE(file.empty());
  Hierarchy h = load_hierarchy(file);
  ASSERT_NE(test::flip_a_quad_diagonal(h), kNone);
  save_hierarchy(h, file);

  start({});
  EXPECT_GT(frame_after_pose(id, editor, 0.5f).vertex_count(), 0u);
  v1::JoinSessionRequest jr;
  jr.set_session_id(id);
  ASSERT_TRUE(stub_->JoinSession(context(id, editor).get(), jr, &info).ok());
  EXPECT_EQ(info.options().threshold(), 0.0);  // came back at T = 0

  const grpc::Status refused = stub_->SetOptions(context(id, editor).get(), so, &info);
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_NE(refused.error_message().find("cannot run a finite T"), std::string::npos) << refused.error_message();
  EXPECT_NE(refused.error_message().find("not in its fan"), std::string::npos) << refused.error_message();
  ASSERT_TRUE(stub_->JoinSession(context(id, editor).get(), jr, &info).ok());
  EXPECT_EQ(info.options().threshold(), 0.0);  // the refused request changed nothing
  EXPECT_GT(frame_after_pose(id, editor, 0.75f).vertex_count(), 0u);
}

TEST_F(ServiceTest, UnarySubmitPoseReachesWatchers) {
  const Created c = upload(file_bytes(kBunny), "obj");
  ASSERT_TRUE(c.status.ok());
  const std::string id = c.created.info().session_id(), editor = c.created.editor_token(), viewer = c.created.viewer_token();
  auto wctx = context(id, viewer);
  v1::WatchRequest wr;
  wr.set_session_id(id);
  auto watch = stub_->Watch(wctx.get(), wr);
  v1::Frame f;
  ASSERT_TRUE(watch->Read(&f));  // the current (rest) frame

  v1::DriveRequest pose;
  pose.set_session_id(id);
  pose.set_client_name("browser");
  pose.add_indices(2);
  pose.add_positions(0.5f), pose.add_positions(0.5f), pose.add_positions(0.5f);
  v1::SubmitPoseResponse accepted;
  ASSERT_TRUE(stub_->SubmitPose(context(id, editor).get(), pose, &accepted).ok());
  do {
    ASSERT_TRUE(watch->Read(&f));
  } while (f.version() <= accepted.accepted_at_version());
  ASSERT_EQ(f.changes_size(), 1);
  EXPECT_EQ(f.changes(0).client_name(), "browser");
  EXPECT_EQ(f.changes(0).vertex_count(), 1u);

  EXPECT_EQ(stub_->SubmitPose(context(id, viewer).get(), pose, &accepted).error_code(), grpc::StatusCode::PERMISSION_DENIED);
  pose.add_positions(1.0f);  // 4 coordinates for one index
  EXPECT_EQ(stub_->SubmitPose(context(id, editor).get(), pose, &accepted).error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  wctx->TryCancel();
  watch->Finish();
}

}  // namespace
}  // namespace filigree

namespace filigree {
namespace {

TEST_F(ServiceTest, HandlesOfSeveralClientsMergeIntoTheBasePose) {
  const Created c = upload(file_bytes(kBunny), "obj");
  ASSERT_TRUE(c.status.ok());
  const std::string id = c.created.info().session_id(), editor = c.created.editor_token();
  const v1::RestMesh& rest = c.created.info().rest();
  auto rest_of = [&](int v) { return Vec3(rest.positions(3 * v), rest.positions(3 * v + 1), rest.positions(3 * v + 2)); };

  // One handle moved by t: an as-rigid-as-possible base moves rigidly, so
  // every base vertex moves by t.
  const Vec3 t(0.0, 0.3, 0.0);
  v1::SetHandlesRequest one;
  one.set_session_id(id);
  one.set_client_name("alice");
  auto* h = one.add_handles();
  h->set_vertex(100);
  const Vec3 target = rest_of(100) + t;
  h->set_x(float(target.x())), h->set_y(float(target.y())), h->set_z(float(target.z()));
  v1::SetHandlesResponse r;
  ASSERT_TRUE(stub_->SetHandles(context(id, editor).get(), one, &r).ok());
  EXPECT_EQ(r.handles_in_session(), 1u);

  auto wait_for_version_after = [&](std::uint64_t v) {
    v1::SessionState state;
    v1::GetStateRequest gr;
    gr.set_session_id(id);
    auto wctx = context(id, editor);
    v1::WatchRequest wr;
    wr.set_session_id(id);
    wr.set_after_version(v);
    auto watch = stub_->Watch(wctx.get(), wr);
    v1::Frame f;
    bool read = false;
    // after_version 0 also yields the current frame first.
    while ((read = watch->Read(&f)) && f.version() <= v) {
    }
    EXPECT_TRUE(read) << "the watch ended before a frame after version " << v;
    wctx->TryCancel();
    watch->Finish();
    EXPECT_TRUE(stub_->GetState(context(id, editor).get(), gr, &state).ok());
    return state;
  };
  v1::SessionState state = wait_for_version_after(r.accepted_at_version());
  const auto& base = c.created.info().base();
  for (int i = 0; i < base.original_ids_size(); ++i)
    for (int k = 0; k < 3; ++k) ASSERT_NEAR(state.pose(3 * i + k), base.positions(3 * i + k) + t[k], 1e-3) << i;

  // Bob adds a handle elsewhere, holding it in place: both count.
  v1::SetHandlesRequest other;
  other.set_session_id(id);
  other.set_client_name("bob");
  auto* hb = other.add_handles();
  hb->set_vertex(1500);
  hb->set_x(rest.positions(4500)), hb->set_y(rest.positions(4501)), hb->set_z(rest.positions(4502));
  ASSERT_TRUE(stub_->SetHandles(context(id, editor).get(), other, &r).ok());
  EXPECT_EQ(r.handles_in_session(), 2u);
  state = wait_for_version_after(r.accepted_at_version());
  bool saw_bob = false;
  for (const auto& ch : state.frame().changes()) saw_bob |= ch.client_name() == "bob";
  EXPECT_TRUE(saw_bob);

  // Every page sees everyone's handles, with a viewer token: by name, each
  // client's in the order it set them.
  auto handles_now = [&] {
    v1::GetHandlesRequest gh;
    gh.set_session_id(id);
    v1::SessionHandles out;
    EXPECT_TRUE(stub_->GetHandles(context(id, c.created.viewer_token()).get(), gh, &out).ok());
    return out;
  };
  auto listed = [](const v1::SessionHandles& all) {
    std::vector<std::pair<std::string, std::vector<std::uint32_t>>> out;
    for (const auto& p : all.participants()) {
      out.push_back({p.client_name(), {}});
      for (const auto& hh : p.handles()) out.back().second.push_back(hh.vertex());
    }
    return out;
  };
  // Carol's two handles, given in falling vertex order, and one on Bob's vertex.
  v1::SetHandlesRequest carol;
  carol.set_session_id(id);
  carol.set_client_name("carol");
  for (int v : {700, 200, 1500}) {
    auto* hc = carol.add_handles();
    hc->set_vertex(v);
    hc->set_x(rest.positions(3 * v) + 0.05f), hc->set_y(rest.positions(3 * v + 1)), hc->set_z(rest.positions(3 * v + 2));
  }
  ASSERT_TRUE(stub_->SetHandles(context(id, editor).get(), carol, &r).ok());
  v1::SessionHandles all = handles_now();
  EXPECT_EQ(listed(all), (std::vector<std::pair<std::string, std::vector<std::uint32_t>>>{
                             {"alice", {100}}, {"bob", {1500}}, {"carol", {700, 200, 1500}}}));
  ASSERT_EQ(all.participants_size(), 3);
  EXPECT_FLOAT_EQ(all.participants(0).handles(0).y(), float(target.y()));
  EXPECT_FLOAT_EQ(all.participants(2).handles(0).x(), rest.positions(2100) + 0.05f);
  ASSERT_TRUE(stub_->SetHandles(context(id, editor).get(), [&] { auto none = carol; none.clear_handles(); return none; }(), &r).ok());

  // Alice clears hers: Bob's remains.
  v1::SetHandlesRequest clear;
  clear.set_session_id(id);
  clear.set_client_name("alice");
  ASSERT_TRUE(stub_->SetHandles(context(id, editor).get(), clear, &r).ok());
  EXPECT_EQ(r.handles_in_session(), 1u);
  EXPECT_EQ(listed(handles_now()), (std::vector<std::pair<std::string, std::vector<std::uint32_t>>>{{"bob", {1500}}}));
  v1::GetHandlesRequest unknown;
  unknown.set_session_id("no-such-session");
  v1::SessionHandles none;
  EXPECT_EQ(stub_->GetHandles(context("no-such-session", editor).get(), unknown, &none).error_code(), grpc::StatusCode::NOT_FOUND);

  // Two clients on one vertex: the newest call's target is the one solved
  // (documented in SetHandles), whoever holds the vertex longer.
  auto hold = [&](const std::string& client, const Vec3& offset) {
    v1::SetHandlesRequest r;
    r.set_session_id(id);
    r.set_client_name(client);
    auto* hh = r.add_handles();
    hh->set_vertex(100);
    const Vec3 at = rest_of(100) + offset;
    hh->set_x(float(at.x())), hh->set_y(float(at.y())), hh->set_z(float(at.z()));
    v1::SetHandlesResponse answer;
    EXPECT_TRUE(stub_->SetHandles(context(id, editor).get(), r, &answer).ok());
    return answer.accepted_at_version();
  };
  // Where vertex 100 is in the first frame after `accepted`: at the winning
  // target, far from the other one (they are 0.32 apart).
  auto followed = [&](std::uint64_t accepted, const Vec3& winner, const Vec3& loser) {
    const v1::SessionState now = wait_for_version_after(accepted);
    const Vec3 at = rest_of(100) + decode(now.frame())[100];
    EXPECT_LT((at - (rest_of(100) + winner)).norm(), 0.25 * (winner - loser).norm())
        << "vertex 100 at " << at.transpose() << ", the newest target " << (rest_of(100) + winner).transpose();
  };
  const Vec3 by_bob(0.0, 0.0, -0.25), by_carol(0.2, 0.0, 0.0);
  hold("bob", by_bob);                                    // bob's only handle now: vertex 100
  followed(hold("carol", by_carol), by_carol, by_bob);    // the newer of the two
  followed(hold("bob", by_bob), by_bob, by_carol);        // and again

  v1::SetHandlesRequest bad = one;
  bad.mutable_handles(0)->set_vertex(1839);
  EXPECT_EQ(stub_->SetHandles(context(id, editor).get(), bad, &r).error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(stub_->SetHandles(context(id, c.created.viewer_token()).get(), one, &r).error_code(),
            grpc::StatusCode::PERMISSION_DENIED);
}

}  // namespace
}  // namespace filigree

namespace filigree {
namespace {

TEST_F(ServiceTest, OverlaysShowRegionsThatFollowTheThreshold) {
  const Created c = upload(file_bytes(kBunny), "obj");
  ASSERT_TRUE(c.status.ok());
  const std::string id = c.created.info().session_id(), editor = c.created.editor_token();
  v1::Frame f;
  const auto watch = open_watch(id, editor, f);

  // Ask for overlays (the first answer may not be ready), then follow frames
  // until one carries them; bounded by frames, not time.
  std::uint64_t requested_at = 0;  // overlays must describe a frame after this version
  auto overlays_after_next_frames = [&]() {
    v1::GetOverlaysRequest req;
    req.set_session_id(id);
    v1::Overlays o;
    for (int attempt = 0; attempt < 20; ++attempt) {
      EXPECT_TRUE(stub_->GetOverlays(context(id, c.created.viewer_token()).get(), req, &o).ok());
      if (o.ready() && o.version() > requested_at && o.version() == f.version()) return o;
      EXPECT_TRUE(watch->reader->Read(&f));
    }
    return o;
  };
  auto set_threshold = [&](double t) {
    v1::SetOptionsRequest so;
    so.set_session_id(id);
    so.set_threshold(t);
    v1::SessionInfo info;
    EXPECT_TRUE(stub_->SetOptions(context(id, editor).get(), so, &info).ok());
  };
  auto bend = [&](std::uint64_t pose_id, double phase) {
    const Pose p = procedural_pose(local_hierarchy().base_mesh().positions, Motion::kBend, phase);
    v1::DriveRequest r;
    r.set_session_id(id);
    r.set_pose_id(pose_id);
    for (float x : pose_floats(p)) r.add_positions(x);
    v1::SubmitPoseResponse a;
    EXPECT_TRUE(stub_->SubmitPose(context(id, editor).get(), r, &a).ok());
    requested_at = std::max(requested_at, a.accepted_at_version());
  };

  set_threshold(1e5);
  for (int i = 1; i <= 5; ++i) bend(i, 0.2 * i);
  v1::Overlays with_regions = overlays_after_next_frames();
  ASSERT_TRUE(with_regions.ready());
  EXPECT_EQ(with_regions.region_of_size(), 1839);
  EXPECT_GT(with_regions.region_count(), 0u);
  EXPECT_EQ(with_regions.cut_faces_size() % 3, 0);
  EXPECT_GT(with_regions.cut_faces_size(), 0);

  set_threshold(0.0);
  bend(6, 1.0);  // its accepted version is the barrier: the threshold is applied with it
  v1::Overlays direct = overlays_after_next_frames();
  ASSERT_TRUE(direct.ready());
  EXPECT_EQ(direct.region_count(), 0u);
  EXPECT_EQ(direct.cut_faces_size(), 3 * 3674);  // every node recovered: the original mesh
}

// ---------------------------------------------------------------- chunked frames

// A client's view of a chunked stream: KeyedDeltas fed every frame it reads.
struct ChunkedClient {
  explicit ChunkedClient(std::size_t n) : deltas(n) {}
  void apply(const v1::Frame& f) {
    std::vector<DeltaChunkView> views;
    for (const v1::DeltaChunk& c : f.chunks())
      views.push_back({c.first_vertex(), c.vertex_count(), {c.runs().data(), std::size_t(c.runs_size())}, c.deltas()});
    deltas.apply(f.version(), f.keyframe_version(), views);
    version = f.version();
    max_error = f.max_error();
  }
  KeyedDeltas deltas;
  std::uint64_t version = 0;
  float max_error = 0.0f;
};

// A partial pose moving the base vertices within 10% of the diagonal of base
// vertex `centre` up by h·diagonal.
v1::DriveRequest local_pose(const v1::BaseMesh& base, int centre, double h, std::uint64_t pose_id) {
  std::vector<Vec3> points;
  for (int i = 0; i + 2 < base.positions_size(); i += 3) points.emplace_back(base.positions(i), base.positions(i + 1), base.positions(i + 2));
  const double diag = bounding_box_diagonal(points);
  h *= diag;
  v1::DriveRequest r;
  r.set_pose_id(pose_id);
  r.set_frame_format(v1::FRAME_FORMAT_CHUNKED);
  const Vec3 c(base.positions(3 * centre), base.positions(3 * centre + 1), base.positions(3 * centre + 2));
  for (int i = 0; 3 * i < base.positions_size(); ++i) {
    const Vec3 p(base.positions(3 * i), base.positions(3 * i + 1), base.positions(3 * i + 2));
    if ((p - c).norm() > 0.1 * diag) continue;
    r.add_indices(static_cast<std::uint32_t>(i));
    r.add_positions(float(p.x())), r.add_positions(float(p.y() + h)), r.add_positions(float(p.z()));
  }
  return r;
}

TEST_F(ServiceTest, ChunkedFramesSparseLateJoinerAndSkippingWatcher) {
  const Created c = upload(file_bytes(kBunny), "obj");
  ASSERT_TRUE(c.status.ok());
  const std::string id = c.created.info().session_id();
  const std::size_t n = c.created.info().rest().vertex_count();
  const v1::BaseMesh& base = c.created.info().base();

  // A watcher that reads nothing until the end: it skips frames.
  auto stalled_ctx = context(id, c.created.viewer_token());
  v1::WatchRequest wr;
  wr.set_session_id(id);
  wr.set_frame_format(v1::FRAME_FORMAT_CHUNKED);
  auto stalled = stub_->Watch(stalled_ctx.get(), wr);

  auto ctx = context(id, c.created.editor_token());
  auto drive = stub_->Drive(ctx.get());
  ChunkedClient driver(n);
  int sparse = 0;
  constexpr std::uint64_t kPoses = 12;
  for (std::uint64_t p = 1; p <= kPoses; ++p) {
    v1::DriveRequest r = local_pose(base, static_cast<int>(p % 3) * 40, 0.01 * double(p), p);
    r.set_session_id(id);
    ASSERT_TRUE(drive->Write(r));
    v1::Frame f;
    do {
      ASSERT_TRUE(drive->Read(&f));
      ASSERT_FALSE(f.chunks().empty() && f.keyframe_version() == 0 && f.version() != 0) << "chunked frames name their keyframe";
      driver.apply(f);
      if (f.keyframe_version() != f.version()) ++sparse;
    } while (f.pose_id() != p);
  }
  EXPECT_GT(sparse, 0) << "local edits make sparse frames";

  // The same state as one buffer, from GetState in the default format.
  v1::GetStateRequest gr;
  gr.set_session_id(id);
  v1::SessionState single;
  ASSERT_TRUE(stub_->GetState(context(id, c.created.viewer_token()).get(), gr, &single).ok());
  ASSERT_EQ(single.frame().version(), driver.version);
  ASSERT_TRUE(single.frame().chunks().empty());
  const std::vector<Vec3> reference = decode(single.frame());
  const auto expect_matches = [&](const ChunkedClient& client, const char* who) {
    ASSERT_EQ(client.version, single.frame().version()) << who;
    const double tolerance = double{client.max_error} + single.frame().max_error() + 1e-7;
    for (std::size_t i = 0; i < n; ++i)
      for (int k = 0; k < 3; ++k)
        ASSERT_NEAR(client.deltas.deltas()[3 * i + k], reference[i][k], tolerance) << who << ", vertex " << i;
  };
  expect_matches(driver, "the driver");

  // A late joiner: the keyframe comes first, then the current frame.
  auto late_ctx = context(id, c.created.viewer_token());
  auto late = stub_->Watch(late_ctx.get(), wr);
  ChunkedClient joiner(n);
  v1::Frame f;
  ASSERT_TRUE(late->Read(&f));
  EXPECT_EQ(f.keyframe_version(), f.version()) << "a late joiner's first frame is a keyframe";
  joiner.apply(f);
  if (joiner.version != driver.version) {
    ASSERT_TRUE(late->Read(&f));
    joiner.apply(f);
  }
  expect_matches(joiner, "the late joiner");

  // The stalled watcher now reads what it was left: every frame decodes.
  ChunkedClient skipper(n);
  while (skipper.version != driver.version && stalled->Read(&f)) skipper.apply(f);
  expect_matches(skipper, "the watcher that skipped frames");

  // GetState in the chunked format: the frame and, when sparse, its keyframe.
  gr.set_frame_format(v1::FRAME_FORMAT_CHUNKED);
  v1::SessionState chunked;
  ASSERT_TRUE(stub_->GetState(context(id, c.created.viewer_token()).get(), gr, &chunked).ok());
  ChunkedClient from_state(n);
  if (chunked.has_keyframe()) from_state.apply(chunked.keyframe());
  from_state.apply(chunked.frame());
  expect_matches(from_state, "GetState (chunked)");

  // A requested keyframe: the next frame lists every vertex.
  v1::DriveRequest key;
  key.set_session_id(id);
  key.set_request_keyframe(true);
  ASSERT_TRUE(drive->Write(key));
  ASSERT_TRUE(drive->Read(&f));
  EXPECT_EQ(f.keyframe_version(), f.version());
  EXPECT_EQ(f.stats().present_vertices(), n);

  // A watcher in the default (single-buffer) format of a frame made without
  // one: the frame transcoded for it (on a job thread), same version.
  ASSERT_FALSE(f.chunks().empty()) << "the current frame must be chunked for the watcher to need a transcode";
  auto single_ctx = context(id, c.created.viewer_token());
  v1::WatchRequest single_request;
  single_request.set_session_id(id);
  auto single_watch = stub_->Watch(single_ctx.get(), single_request);
  v1::Frame single_frame;
  ASSERT_TRUE(single_watch->Read(&single_frame));
  EXPECT_EQ(single_frame.version(), f.version());
  EXPECT_TRUE(single_frame.chunks().empty());
  ChunkedClient keyed(n);
  keyed.apply(f);
  const std::vector<Vec3> transcoded = decode(single_frame);
  for (std::size_t i = 0; i < n; ++i)
    for (int k = 0; k < 3; ++k)
      ASSERT_NEAR(transcoded[i][k], keyed.deltas.deltas()[3 * i + k], double{single_frame.max_error()} + 1e-7) << "vertex " << i;
  single_ctx->TryCancel();
  single_watch->Finish();

  drive->WritesDone();
  while (drive->Read(&f)) {
  }
  EXPECT_TRUE(drive->Finish().ok());
  for (auto* c2 : {stalled_ctx.get(), late_ctx.get()}) c2->TryCancel();
  while (stalled->Read(&f)) {
  }
  while (late->Read(&f)) {
  }
  stalled->Finish();
  late->Finish();
}

// 8 sessions driven at once on the server's shared scheduler: every one gets
// every frame it asked for (none starves behind the others).
TEST_F(ServiceTest, EightSessionsDrivenAtOnceAllProgress) {
  const std::string bytes = file_bytes(kBunny);
  std::vector<Created> sessions;
  for (int i = 0; i < 8; ++i) {
    sessions.push_back(upload(bytes, "obj"));
    ASSERT_TRUE(sessions.back().status.ok());
  }
  constexpr std::uint64_t kPoses = 15;
  std::vector<std::uint64_t> answered(sessions.size(), 0);
  std::vector<std::thread> drivers;
  for (std::size_t s = 0; s < sessions.size(); ++s)
    drivers.emplace_back([&, s] {
      const auto& info = sessions[s].created.info();
      auto ctx = context(info.session_id(), sessions[s].created.editor_token());
      auto drive = stub_->Drive(ctx.get());
      std::vector<Vec3> base_rest;
      for (int k = 0; k + 2 < info.base().positions_size(); k += 3)
        base_rest.emplace_back(info.base().positions(k), info.base().positions(k + 1), info.base().positions(k + 2));
      for (std::uint64_t p = 1; p <= kPoses; ++p) {
        v1::DriveRequest r;
        r.set_session_id(info.session_id());
        r.set_pose_id(p);
        r.set_frame_format(v1::FRAME_FORMAT_CHUNKED);
        for (float x : pose_floats(procedural_pose(base_rest, Motion::kTwist, 0.1 * double(p)))) r.add_positions(x);
        if (!drive->Write(r)) return;
        v1::Frame f;
        do {
          if (!drive->Read(&f)) return;
        } while (f.pose_id() != p);
        answered[s] = p;
      }
      drive->WritesDone();
      v1::Frame f;
      while (drive->Read(&f)) {
      }
      drive->Finish();
    });
  for (auto& t : drivers) t.join();
  for (std::size_t s = 0; s < sessions.size(); ++s) EXPECT_EQ(answered[s], kPoses) << "session " << s;
}

}  // namespace
}  // namespace filigree
