// The edit history end to end, against a filigree-server child over gRPC and
// the contract alone: three editors interleave changes and undo their own,
// conflicts are reported with who and what, redo, a drag as one entry,
// checkpoints restored and diffed, history across SIGKILL, presence for a late
// joiner, the history exported as full-detail frames, refused requests.

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "codec/delta_codec.h"
#include "filigree/v1/filigree.grpc.pb.h"
#include "support/grpc_upload.h"
#include "support/server_process.h"
#include "support/test_meshes.h"

namespace filigree {
namespace {

using test::ServerProcess;

class HistoryTest : public ::testing::Test {
 protected:
  void SetUp() override {
    data_dir_ = std::filesystem::path(::testing::TempDir()) /
                ("filigree_history_" + std::to_string(::getpid()) + "_" + ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::remove_all(data_dir_);
    start();
    const test::Uploaded up = test::upload_mesh(*stub_, test::file_bytes(test::shipped_path("bunny_small.obj")), "obj", 150);
    ASSERT_TRUE(up.status.ok()) << up.status.error_message();
    id_ = up.created.info().session_id();
    editor_ = up.created.editor_token();
    viewer_ = up.created.viewer_token();
    rest_.assign(up.created.info().base().positions().begin(), up.created.info().base().positions().end());
  }
  void TearDown() override {
    server_.reset();
    std::filesystem::remove_all(data_dir_);
  }
  void start() {
    server_ = std::make_unique<ServerProcess>(FILIGREE_SERVER_BINARY, std::vector<std::string>{"--data-dir", data_dir_.string()});
    stub_ = v1::Filigree::NewStub(grpc::CreateChannel(server_->address(), grpc::InsecureChannelCredentials()));
  }

  std::unique_ptr<grpc::ClientContext> context(const std::string& token) const {
    auto c = std::make_unique<grpc::ClientContext>();
    c->AddMetadata("x-filigree-token", token);
    c->AddMetadata("x-session-id", id_);
    return c;
  }

  // `author` moves base vertices `vertices` up by `dy` from rest (a unary
  // pose, as a browser sends), in gesture `gesture`.
  void move(const std::string& author, const std::vector<std::uint32_t>& vertices, float dy, std::uint64_t gesture) {
    v1::DriveRequest r;
    r.set_session_id(id_);
    r.set_client_name(author);
    r.set_gesture_id(gesture);
    for (std::uint32_t v : vertices) {
      r.add_indices(v);
      r.add_positions(rest_[3 * v]);
      r.add_positions(rest_[3 * v + 1] + dy);
      r.add_positions(rest_[3 * v + 2]);
    }
    v1::SubmitPoseResponse answer;
    auto ctx = context(editor_);
    const grpc::Status s = stub_->SubmitPose(ctx.get(), r, &answer);
    ASSERT_TRUE(s.ok()) << s.error_message();
  }
  v1::UndoResponse undo(const std::string& author, bool redo = false, bool force = false) {
    v1::UndoRequest r;
    r.set_session_id(id_);
    r.set_client_name(author);
    r.set_force(force);
    v1::UndoResponse answer;
    auto ctx = context(editor_);
    const grpc::Status s = redo ? stub_->Redo(ctx.get(), r, &answer) : stub_->Undo(ctx.get(), r, &answer);
    EXPECT_TRUE(s.ok()) << s.error_message();
    return answer;
  }
  // Each base vertex's height above rest in the merged pose.
  std::vector<float> heights() {
    v1::GetStateRequest r;
    r.set_session_id(id_);
    v1::SessionState state;
    auto ctx = context(viewer_);
    EXPECT_TRUE(stub_->GetState(ctx.get(), r, &state).ok());
    std::vector<float> out;
    for (std::size_t v = 0; 3 * v < rest_.size(); ++v) out.push_back(state.pose(static_cast<int>(3 * v + 1)) - rest_[3 * v + 1]);
    return out;
  }
  v1::History history() {
    v1::GetHistoryRequest r;
    r.set_session_id(id_);
    v1::History h;
    auto ctx = context(viewer_);
    EXPECT_TRUE(stub_->GetHistory(ctx.get(), r, &h).ok());
    return h;
  }
  // The heights expected: zero but for `set`.
  std::vector<float> expect(std::initializer_list<std::pair<std::uint32_t, float>> set) const {
    std::vector<float> out(rest_.size() / 3, 0.0f);
    for (const auto& [v, h] : set) out[v] = h;
    return out;
  }
  static void expect_heights(const std::vector<float>& got, const std::vector<float>& want) {
    ASSERT_EQ(got.size(), want.size());
    for (std::size_t v = 0; v < got.size(); ++v) EXPECT_NEAR(got[v], want[v], 1e-6) << "base vertex " << v;
  }

  std::filesystem::path data_dir_;
  std::unique_ptr<ServerProcess> server_;
  std::unique_ptr<v1::Filigree::Stub> stub_;
  std::string id_, editor_, viewer_;
  std::vector<float> rest_;
};

TEST_F(HistoryTest, ThreeEditorsUndoTheirOwnGesturesAndKeepTheOthersWork) {
  // Interleaved: Ana's drag of 1–2 (two poses, one gesture), Ben on 3 and 2
  // (over Ana's 2), Cleo on 4, Ana again on 5.
  move("ana", {1, 2}, 0.01f, 11);
  move("ben", {3}, 0.02f, 21);
  move("ana", {1, 2}, 0.03f, 11);
  move("cleo", {4}, 0.04f, 31);
  move("ben", {2}, 0.05f, 22);
  move("ana", {5}, 0.06f, 12);
  expect_heights(heights(), expect({{1, 0.03f}, {2, 0.05f}, {3, 0.02f}, {4, 0.04f}, {5, 0.06f}}));
  const v1::History h = history();
  ASSERT_EQ(h.entries_size(), 5) << "Ana's two poses of gesture 11 are one entry";

  // Ana's undo: her gesture 12 (vertex 5) only.
  v1::UndoResponse a = undo("ana");
  EXPECT_EQ(a.outcome(), v1::UndoResponse::OUTCOME_DONE);
  expect_heights(heights(), expect({{1, 0.03f}, {2, 0.05f}, {3, 0.02f}, {4, 0.04f}}));
  // Again: gesture 11, but Ben changed vertex 2 since: it keeps his value.
  a = undo("ana");
  EXPECT_EQ(a.outcome(), v1::UndoResponse::OUTCOME_PARTIAL);
  ASSERT_EQ(a.conflicts_size(), 1);
  EXPECT_EQ(a.conflicts(0).author(), "ben");
  EXPECT_EQ(std::vector<std::uint32_t>(a.conflicts(0).base_vertices().begin(), a.conflicts(0).base_vertices().end()),
            std::vector<std::uint32_t>{2});
  expect_heights(heights(), expect({{2, 0.05f}, {3, 0.02f}, {4, 0.04f}}));
  // Ben's undo of his vertex-2 change gives back what it found: Ana's 0.03.
  EXPECT_EQ(undo("ben").outcome(), v1::UndoResponse::OUTCOME_DONE);
  expect_heights(heights(), expect({{2, 0.03f}, {3, 0.02f}, {4, 0.04f}}));
  // Cleo's redo has nothing; her undo and redo round-trip.
  EXPECT_EQ(undo("cleo", /*redo=*/true).outcome(), v1::UndoResponse::OUTCOME_NOTHING);
  undo("cleo");
  expect_heights(heights(), expect({{2, 0.03f}, {3, 0.02f}}));
  EXPECT_EQ(undo("cleo", /*redo=*/true).outcome(), v1::UndoResponse::OUTCOME_DONE);
  expect_heights(heights(), expect({{2, 0.03f}, {3, 0.02f}, {4, 0.04f}}));
  // Ana's redo brings gesture 11 back on vertex 1 (vertex 2 was not hers to restore).
  EXPECT_EQ(undo("ana", true).outcome(), v1::UndoResponse::OUTCOME_DONE);
  expect_heights(heights(), expect({{1, 0.03f}, {2, 0.03f}, {3, 0.02f}, {4, 0.04f}}));
}

TEST_F(HistoryTest, AnUndoOfVerticesOthersChangedSinceChangesNothingUnlessForced) {
  move("ana", {7}, 0.01f, 1);
  move("ben", {7}, 0.02f, 2);
  const v1::UndoResponse a = undo("ana");
  EXPECT_EQ(a.outcome(), v1::UndoResponse::OUTCOME_CONFLICT);
  EXPECT_EQ(a.conflicts(0).author(), "ben");
  EXPECT_NE(a.message().find("others changed"), std::string::npos) << a.message();
  expect_heights(heights(), expect({{7, 0.02f}}));
  EXPECT_EQ(undo("ana", false, /*force=*/true).outcome(), v1::UndoResponse::OUTCOME_DONE);
  expect_heights(heights(), expect({}));
}

TEST_F(HistoryTest, ADriveStreamsGestureIsOneEntry) {
  auto ctx = context(editor_);
  auto drive = stub_->Drive(ctx.get());
  for (std::uint64_t p = 1; p <= 20; ++p) {
    v1::DriveRequest r;
    r.set_session_id(id_);
    r.set_client_name("dragger");
    r.set_pose_id(p);
    r.set_gesture_id(99);
    r.add_indices(9);
    r.add_positions(rest_[27]);
    r.add_positions(rest_[28] + 0.001f * static_cast<float>(p));
    r.add_positions(rest_[29]);
    ASSERT_TRUE(drive->Write(r));
  }
  drive->WritesDone();
  v1::Frame f;
  while (drive->Read(&f)) {
  }
  ASSERT_TRUE(drive->Finish().ok());
  const v1::History h = history();
  ASSERT_EQ(h.entries_size(), 1);
  EXPECT_EQ(h.entries(0).author(), "dragger");
  EXPECT_EQ(h.entries(0).gesture_id(), 99u);
  undo("dragger");
  expect_heights(heights(), expect({}));
}

TEST_F(HistoryTest, CheckpointsRestoreAndDiffAndTheRestoreUndoes) {
  move("ana", {1}, 0.01f, 1);
  v1::CreateCheckpointRequest c;
  c.set_session_id(id_);
  c.set_name("before the review");
  c.set_client_name("ana");
  v1::Checkpoint made;
  auto ctx = context(editor_);
  ASSERT_TRUE(stub_->CreateCheckpoint(ctx.get(), c, &made).ok());
  move("ben", {2, 3}, 0.02f, 2);
  v1::DiffCheckpointRequest d;
  d.set_session_id(id_);
  d.set_checkpoint(made.id());
  v1::CheckpointDiff diff;
  ctx = context(viewer_);
  ASSERT_TRUE(stub_->DiffCheckpoint(ctx.get(), d, &diff).ok());
  EXPECT_EQ(std::vector<std::uint32_t>(diff.base_vertices().begin(), diff.base_vertices().end()), (std::vector<std::uint32_t>{2, 3}));
  EXPECT_NEAR(diff.max_distance(), 0.02, 1e-6);
  v1::RestoreCheckpointRequest r;
  r.set_session_id(id_);
  r.set_checkpoint(made.id());
  r.set_client_name("cleo");
  v1::UndoResponse restored;
  ctx = context(editor_);
  ASSERT_TRUE(stub_->RestoreCheckpoint(ctx.get(), r, &restored).ok());
  EXPECT_EQ(restored.outcome(), v1::UndoResponse::OUTCOME_DONE);
  expect_heights(heights(), expect({{1, 0.01f}}));
  EXPECT_EQ(undo("cleo").outcome(), v1::UndoResponse::OUTCOME_DONE);
  expect_heights(heights(), expect({{1, 0.01f}, {2, 0.02f}, {3, 0.02f}}));
  r.set_checkpoint(made.id() + 100);
  ctx = context(editor_);
  EXPECT_EQ(stub_->RestoreCheckpoint(ctx.get(), r, &restored).error_code(), grpc::StatusCode::NOT_FOUND);
}

TEST_F(HistoryTest, TheHistorySurvivesSigkill) {
  move("ana", {1}, 0.01f, 1);
  move("ben", {2}, 0.02f, 2);
  undo("ben");  // answered: its history is on disk
  const v1::History before = history();
  server_->kill_now();
  start();
  const v1::History after = history();
  ASSERT_EQ(after.entries_size(), before.entries_size());
  for (int i = 0; i < after.entries_size(); ++i)
    EXPECT_EQ(after.entries(i).SerializeAsString(), before.entries(i).SerializeAsString()) << "entry " << i;
  // And it goes on: Ben's redo, then Ana's undo.
  EXPECT_EQ(undo("ben", true).outcome(), v1::UndoResponse::OUTCOME_DONE);
  EXPECT_EQ(undo("ana").outcome(), v1::UndoResponse::OUTCOME_DONE);
  expect_heights(heights(), expect({{2, 0.02f}}));
}

TEST_F(HistoryTest, PresenceReachesALateJoiner) {
  // Ana watches and points; Cleo changes a vertex; Ben joins late.
  auto ana_ctx = context(viewer_);
  v1::WatchPresenceRequest w;
  w.set_session_id(id_);
  w.set_client_name("ana");
  auto ana = stub_->WatchPresence(ana_ctx.get(), w);
  v1::Presence p;
  ASSERT_TRUE(ana->Read(&p));
  v1::SetPresenceRequest point;
  point.set_session_id(id_);
  point.set_client_name("ana");
  point.set_has_pointer(true);
  point.set_pointer_x(0.5f);
  point.set_pointer_vertex(12);
  v1::SetPresenceResponse ignored;
  auto ctx = context(viewer_);
  ASSERT_TRUE(stub_->SetPresence(ctx.get(), point, &ignored).ok());
  move("cleo", {4, 5}, 0.01f, 1);
  w.set_client_name("ben");
  auto ben_ctx = context(viewer_);
  auto ben = stub_->WatchPresence(ben_ctx.get(), w);
  ASSERT_TRUE(ben->Read(&p));
  std::map<std::string, v1::Participant> by_name;
  for (const v1::Participant& q : p.participants()) by_name[q.client_name()] = q;
  ASSERT_TRUE(by_name.contains("ana"));
  ASSERT_TRUE(by_name.contains("ben"));
  ASSERT_TRUE(by_name.contains("cleo"));
  EXPECT_TRUE(by_name["ana"].has_pointer());
  EXPECT_EQ(by_name["ana"].pointer_vertex(), 12u);
  EXPECT_EQ(by_name["ana"].role(), v1::Participant::ROLE_VIEWER);
  EXPECT_EQ(by_name["cleo"].role(), v1::Participant::ROLE_EDITOR);
  EXPECT_EQ(std::vector<std::uint32_t>(by_name["cleo"].touching().begin(), by_name["cleo"].touching().end()),
            (std::vector<std::uint32_t>{4, 5}));
  EXPECT_EQ(by_name["ana"].colour().size(), 7u);
  EXPECT_EQ(by_name["ana"].colour()[0], '#');
  // Ana's stream sees Ben arrive.
  bool saw_ben = false;
  while (!saw_ben && ana->Read(&p))
    for (const v1::Participant& q : p.participants()) saw_ben |= q.client_name() == "ben";
  EXPECT_TRUE(saw_ben);
  ana_ctx->TryCancel();
  ben_ctx->TryCancel();
  ana->Finish();
  ben->Finish();
}

TEST_F(HistoryTest, TheExportedHistoryEndsAtTheCurrentFrame) {
  move("ana", {1, 2, 3}, 0.05f, 1);
  move("ben", {10}, -0.04f, 2);
  // The current frame (single buffer), after both changes.
  auto wctx = context(viewer_);
  v1::WatchRequest wr;
  wr.set_session_id(id_);
  auto watch = stub_->Watch(wctx.get(), wr);
  v1::Frame current;
  const std::uint64_t newest = history().entries(1).version();
  do {
    ASSERT_TRUE(watch->Read(&current));
  } while (current.version() <= newest);
  wctx->TryCancel();
  watch->Finish();
  v1::ExportHistoryRequest r;
  r.set_session_id(id_);
  auto ctx = context(viewer_);
  auto exported = stub_->ExportHistory(ctx.get(), r);
  std::vector<v1::HistoryFrame> frames;
  v1::HistoryFrame f;
  while (exported->Read(&f)) frames.push_back(f);
  ASSERT_TRUE(exported->Finish().ok());
  ASSERT_EQ(frames.size(), 2u);
  EXPECT_EQ(frames[0].author(), "ana");
  EXPECT_EQ(frames[1].author(), "ben");
  // The first state has Ana's change only.
  EXPECT_NEAR(frames[0].base_pose(3 * 10 + 1), rest_[3 * 10 + 1], 1e-7);
  EXPECT_NEAR(frames[0].base_pose(3 * 1 + 1), rest_[3 * 1 + 1] + 0.05f, 1e-6);
  // The last state's frame is the frame the session sent for it.
  EncodedDeltas a{frames[1].frame().deltas(), frames[1].frame().vertex_count(), frames[1].frame().quantization_bits(),
                  frames[1].frame().delta_min(), frames[1].frame().delta_range(), frames[1].frame().max_error()};
  EncodedDeltas b{current.deltas(), current.vertex_count(), current.quantization_bits(), current.delta_min(),
                  current.delta_range(), current.max_error()};
  const std::vector<Vec3> da = decode_deltas(a), db = decode_deltas(b);
  ASSERT_EQ(da.size(), db.size());
  double worst = 0.0, largest = 0.0;
  for (std::size_t v = 0; v < da.size(); ++v) {
    worst = std::max(worst, (da[v] - db[v]).cwiseAbs().maxCoeff());
    largest = std::max(largest, db[v].cwiseAbs().maxCoeff());
  }
  EXPECT_LE(worst, double{a.max_error} + double{b.max_error});
  EXPECT_GT(largest, 0.01);
}

TEST_F(HistoryTest, BadHistoryRequestsAreRefused) {
  v1::UndoRequest r;
  r.set_session_id(id_);
  r.set_client_name(std::string(1000, 'x'));
  v1::UndoResponse answer;
  auto ctx = context(editor_);
  EXPECT_EQ(stub_->Undo(ctx.get(), r, &answer).error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  r.set_client_name("ana");
  ctx = context(viewer_);  // a viewer may not undo
  EXPECT_EQ(stub_->Undo(ctx.get(), r, &answer).error_code(), grpc::StatusCode::PERMISSION_DENIED);
  v1::CreateCheckpointRequest c;
  c.set_session_id(id_);
  c.set_name("");
  v1::Checkpoint made;
  ctx = context(editor_);
  EXPECT_EQ(stub_->CreateCheckpoint(ctx.get(), c, &made).error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  v1::SetPresenceRequest p;
  p.set_session_id(id_);
  p.set_has_pointer(true);
  p.set_pointer_x(std::nanf(""));
  v1::SetPresenceResponse ignored;
  ctx = context(viewer_);
  EXPECT_EQ(stub_->SetPresence(ctx.get(), p, &ignored).error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  p.set_pointer_x(0.0f);
  p.set_pointer_vertex(1u << 30);
  ctx = context(viewer_);
  EXPECT_EQ(stub_->SetPresence(ctx.get(), p, &ignored).error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  v1::ExportHistoryRequest e;
  e.set_session_id(id_);
  e.set_from_entry(5);
  e.set_to_entry(2);
  ctx = context(viewer_);
  auto exported = stub_->ExportHistory(ctx.get(), e);
  v1::HistoryFrame f;
  EXPECT_FALSE(exported->Read(&f));
  EXPECT_EQ(exported->Finish().error_code(), grpc::StatusCode::INVALID_ARGUMENT);
}

}  // namespace
}  // namespace filigree
