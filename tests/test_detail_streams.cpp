// Level-of-detail streams end to end, against a filigree-server child over
// gRPC and the contract alone: a stream with a vertex budget gets the level's
// mesh, then frames of its vertices that sit where the full frame puts them;
// budgets round to shared levels, encoded once per frame whatever the number
// of streams; a live stream switches level; bad budgets are refused.

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <set>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "codec/keyed_deltas.h"
#include "codec/level_mesh_codec.h"
#include "filigree/v1/filigree.grpc.pb.h"
#include "support/grpc_upload.h"
#include "support/server_process.h"
#include "support/test_meshes.h"

namespace filigree {
namespace {

using test::ServerProcess;

// A client's view of one stream: the level it is at and the decoded deltas
// of that level's vertices.
struct LevelClient {
  std::uint32_t level = 0;  // DetailLevel.vertex_count
  std::uint64_t stream_id = 0;
  LevelMesh mesh;  // empty at full detail
  std::unique_ptr<KeyedDeltas> deltas;
  std::uint64_t version = 0;
  float max_error = 0.0f;
  int level_messages = 0;

  // Applies one message; a DetailLevel resets the decoded state.
  void apply(const v1::Frame& f, std::uint32_t full_vertices) {
    if (f.has_level()) {
      ++level_messages;
      level = f.level().vertex_count();
      stream_id = f.level().stream_id();
      mesh = f.level().mesh().empty() ? LevelMesh{} : decode_level_mesh(f.level().mesh(), full_vertices);
      deltas = std::make_unique<KeyedDeltas>(level);
      have_frame = false;  // nothing decoded at this level yet
      return;
    }
    ASSERT_TRUE(deltas) << "a frame before any DetailLevel";
    ASSERT_EQ(f.vertex_count(), level);
    ASSERT_EQ(f.level_vertices(), level == full_vertices ? 0u : level);
    std::vector<DeltaChunkView> views;
    for (const v1::DeltaChunk& c : f.chunks())
      views.push_back({c.first_vertex(), c.vertex_count(), {c.runs().data(), std::size_t(c.runs_size())}, c.deltas()});
    deltas->apply(f.version(), f.keyframe_version(), views);
    version = f.version();
    max_error = f.max_error();
    have_frame = true;
  }
  bool have_frame = false;
  // Original id of level vertex i.
  std::uint32_t original(std::size_t i) const { return mesh.original_ids.empty() ? static_cast<std::uint32_t>(i) : mesh.original_ids[i]; }
};

class DetailStreamsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    data_dir_ = std::filesystem::path(::testing::TempDir()) /
                ("filigree_lod_" + std::to_string(::getpid()) + "_" + ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::remove_all(data_dir_);
    server_ = std::make_unique<ServerProcess>(FILIGREE_SERVER_BINARY, std::vector<std::string>{"--data-dir", data_dir_.string()});
    stub_ = v1::Filigree::NewStub(grpc::CreateChannel(server_->address(), grpc::InsecureChannelCredentials()));
    const test::Uploaded up =
        test::upload_mesh(*stub_, test::file_bytes(test::shipped_path("bunny_small.obj")), "obj", 150);
    ASSERT_TRUE(up.status.ok()) << up.status.error_message();
    id_ = up.created.info().session_id();
    editor_ = up.created.editor_token();
    viewer_ = up.created.viewer_token();
    full_ = up.created.info().rest().vertex_count();
    base_ = up.created.info().base().original_ids_size();
    base_positions_.assign(up.created.info().base().positions().begin(), up.created.info().base().positions().end());
  }
  void TearDown() override {
    server_.reset();
    std::filesystem::remove_all(data_dir_);
  }

  std::unique_ptr<grpc::ClientContext> context(const std::string& token) const {
    auto c = std::make_unique<grpc::ClientContext>();
    c->AddMetadata("x-filigree-token", token);
    c->AddMetadata("x-session-id", id_);
    return c;
  }

  struct Watching {
    std::unique_ptr<grpc::ClientContext> context;
    std::unique_ptr<grpc::ClientReader<v1::Frame>> reader;
    LevelClient client;
    bool finished = false;
    ~Watching() {
      context->TryCancel();
      if (!finished) reader->Finish();
    }
    // Reads until a frame of at least `version` is decoded; false if the stream ends.
    bool read_until(std::uint64_t version, std::uint32_t full) {
      v1::Frame f;
      while (!client.have_frame || client.version < version) {
        if (!reader->Read(&f)) return false;
        client.apply(f, full);
        if (::testing::Test::HasFatalFailure()) return false;
      }
      return true;
    }
  };
  std::unique_ptr<Watching> watch(std::uint32_t max_vertices, v1::FrameFormat format = v1::FRAME_FORMAT_CHUNKED) {
    auto w = std::make_unique<Watching>();
    w->context = context(viewer_);
    v1::WatchRequest r;
    r.set_session_id(id_);
    r.set_frame_format(format);
    r.set_max_vertices(max_vertices);
    w->reader = stub_->Watch(w->context.get(), r);
    if (max_vertices == 0) {  // no level asked: full frames, no DetailLevel
      w->client.level = full_;
      w->client.deltas = std::make_unique<KeyedDeltas>(full_);
    }
    return w;
  }

  // A pose: every base vertex moved by a bend around the y axis of `angle`
  // radians a unit of x; returns the version the frame will exceed.
  std::uint64_t submit_bend(double angle, std::uint64_t pose_id) {
    v1::DriveRequest r;
    r.set_session_id(id_);
    r.set_pose_id(pose_id);
    r.set_client_name("bender");
    for (std::size_t i = 0; 3 * i < base_positions_.size(); ++i) {
      const double x = base_positions_[3 * i], y = base_positions_[3 * i + 1], z = base_positions_[3 * i + 2];
      const double a = angle * x;
      r.add_indices(static_cast<std::uint32_t>(i));
      r.add_positions(static_cast<float>(std::cos(a) * x - std::sin(a) * z));
      r.add_positions(static_cast<float>(y));
      r.add_positions(static_cast<float>(std::sin(a) * x + std::cos(a) * z));
    }
    v1::SubmitPoseResponse answer;
    auto ctx = context(editor_);
    const grpc::Status s = stub_->SubmitPose(ctx.get(), r, &answer);
    EXPECT_TRUE(s.ok()) << s.error_message();
    return answer.accepted_at_version() + 1;
  }

  // Every level vertex sits where the full frame puts its original vertex.
  static void expect_level_matches_full(const LevelClient& level, const LevelClient& full) {
    ASSERT_EQ(level.version, full.version);
    const auto a = level.deltas->deltas(), b = full.deltas->deltas();
    const double tolerance = double{level.max_error} + double{full.max_error};
    double worst = 0.0, largest = 0.0;
    for (std::size_t i = 0; i < level.level; ++i)
      for (int k = 0; k < 3; ++k) {
        worst = std::max(worst, std::abs(double{a[3 * i + k]} - double{b[3 * level.original(i) + k]}));
        largest = std::max(largest, std::abs(double{b[3 * level.original(i) + k]}));
      }
    EXPECT_LE(worst, tolerance) << "level vertices off their full-frame place";
    EXPECT_GT(largest, 100 * tolerance) << "the pose moved nothing: the comparison proves nothing";
  }

  v1::ListSessionsResponse::Entry listed() {
    grpc::ClientContext ctx;
    v1::ListSessionsResponse r;
    EXPECT_TRUE(stub_->ListSessions(&ctx, {}, &r).ok());
    for (const auto& e : r.sessions())
      if (e.session_id() == id_) return e;
    ADD_FAILURE() << "session not listed";
    return {};
  }

  grpc::Status set_detail(std::uint64_t stream, std::uint32_t max_vertices, v1::SetDetailResponse* answer,
                          const std::string& token) {
    v1::SetDetailRequest r;
    r.set_session_id(id_);
    r.set_stream_id(stream);
    r.set_max_vertices(max_vertices);
    auto ctx = context(token);
    return stub_->SetDetail(ctx.get(), r, answer);
  }

  std::filesystem::path data_dir_;
  std::unique_ptr<ServerProcess> server_;
  std::unique_ptr<v1::Filigree::Stub> stub_;
  std::string id_, editor_, viewer_;
  std::uint32_t full_ = 0, base_ = 0;
  std::vector<float> base_positions_;
};

TEST_F(DetailStreamsTest, ALevelsVerticesSitWhereTheFullFrameHasThem) {
  ASSERT_GT(full_, 1024u);
  ASSERT_LT(base_, 512u);
  auto full = watch(0);
  auto level = watch(600);  // → 512
  ASSERT_TRUE(full->read_until(0, full_));
  v1::Frame first;
  ASSERT_TRUE(level->reader->Read(&first));
  ASSERT_TRUE(first.has_level()) << "a level stream starts with its DetailLevel";
  EXPECT_EQ(first.level().vertex_count(), 512u);
  EXPECT_NE(first.level().stream_id(), 0u);
  level->client.apply(first, full_);
  EXPECT_EQ(level->client.mesh.original_ids.size(), 512u);
  EXPECT_EQ(level->client.mesh.faces.size(), 3u * first.level().face_count());
  // A closed mesh of the bunny's topology: every directed edge once, its
  // opposite present, and χ as the full mesh's.
  std::map<std::pair<std::uint32_t, std::uint32_t>, int> directed;
  std::set<std::pair<std::uint32_t, std::uint32_t>> undirected;
  const auto& faces = level->client.mesh.faces;
  for (std::size_t t = 0; t < faces.size(); t += 3)
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t a = faces[t + k], b = faces[t + (k + 1) % 3];
      ++directed[{a, b}];
      undirected.insert({std::min(a, b), std::max(a, b)});
    }
  for (const auto& [e, n] : directed) {
    EXPECT_EQ(n, 1);
    EXPECT_TRUE(directed.contains({e.second, e.first}));
  }
  EXPECT_EQ(512 - static_cast<long>(undirected.size()) + static_cast<long>(faces.size() / 3), 2);

  const std::uint64_t bent = submit_bend(0.8, 1);
  ASSERT_TRUE(full->read_until(bent, full_));
  ASSERT_TRUE(level->read_until(full->client.version, full_));
  expect_level_matches_full(level->client, full->client);
  // The level's frames are that much smaller.
  EXPECT_EQ(level->client.level_messages, 1);
}

TEST_F(DetailStreamsTest, BudgetsBelowTheBaseGetTheBaseAndAboveTheMeshTheMesh) {
  auto tiny = watch(1);
  auto huge = watch(4000000000u);
  ASSERT_TRUE(tiny->read_until(0, full_));
  ASSERT_TRUE(huge->read_until(0, full_));
  EXPECT_EQ(tiny->client.level, base_);
  EXPECT_EQ(tiny->client.mesh.original_ids.size(), base_);
  EXPECT_EQ(huge->client.level, full_);
  EXPECT_TRUE(huge->client.mesh.original_ids.empty()) << "full detail is the rest mesh itself";
  const std::uint64_t bent = submit_bend(0.5, 1);
  auto full = watch(0);
  ASSERT_TRUE(full->read_until(bent, full_));
  ASSERT_TRUE(tiny->read_until(full->client.version, full_));
  ASSERT_TRUE(huge->read_until(full->client.version, full_));
  expect_level_matches_full(tiny->client, full->client);
  expect_level_matches_full(huge->client, full->client);
}

TEST_F(DetailStreamsTest, ALiveStreamSwitchesLevel) {
  auto full = watch(0);
  auto level = watch(300);  // → 256
  ASSERT_TRUE(level->read_until(0, full_));
  ASSERT_EQ(level->client.level, 256u);
  v1::SetDetailResponse answer;
  const grpc::Status s = set_detail(level->client.stream_id, 1100, &answer, viewer_);
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(answer.vertex_count(), 1024u);
  // The next level message, then frames of the new level, with no pose sent.
  v1::Frame f;
  while (level->client.level != 1024u) {
    ASSERT_TRUE(level->reader->Read(&f));
    level->client.apply(f, full_);
  }
  EXPECT_EQ(level->client.level_messages, 2);
  ASSERT_TRUE(level->read_until(0, full_));
  const std::uint64_t bent = submit_bend(-0.6, 1);
  ASSERT_TRUE(full->read_until(bent, full_));
  ASSERT_TRUE(level->read_until(full->client.version, full_));
  expect_level_matches_full(level->client, full->client);
  // And to full detail: the rest mesh's own frames.
  ASSERT_TRUE(set_detail(level->client.stream_id, 1u << 30, &answer, viewer_).ok());
  EXPECT_EQ(answer.vertex_count(), full_);
  while (level->client.level != full_) {
    ASSERT_TRUE(level->reader->Read(&f));
    level->client.apply(f, full_);
  }
  ASSERT_TRUE(level->read_until(full->client.version, full_));
  expect_level_matches_full(level->client, full->client);
}

TEST_F(DetailStreamsTest, StreamsAtOneLevelShareOneEncode) {
  // 600 and 1000 both round to 512: one level, three streams.
  std::vector<std::unique_ptr<Watching>> streams;
  for (std::uint32_t budget : {600u, 1000u, 700u}) streams.push_back(watch(budget));
  for (auto& w : streams) ASSERT_TRUE(w->read_until(0, full_));
  const std::uint64_t before = listed().levels_size() == 1 ? listed().levels(0).frames_encoded() : 0;
  std::uint64_t last = 0;
  for (std::uint64_t pose = 1; pose <= 5; ++pose) last = submit_bend(0.1 * static_cast<double>(pose), pose);
  for (auto& w : streams) ASSERT_TRUE(w->read_until(last, full_));
  const v1::ListSessionsResponse::Entry entry = listed();
  ASSERT_EQ(entry.levels_size(), 1);
  EXPECT_EQ(entry.levels(0).vertex_count(), 512u);
  EXPECT_EQ(entry.levels(0).streams(), 3u);
  // At most one encode per computed frame (some poses coalesce), not one per stream.
  const std::uint64_t encodes = entry.levels(0).frames_encoded() - before;
  EXPECT_GE(encodes, 1u);
  EXPECT_LE(encodes, 5u) << encodes << " level encodes for at most 5 frames and 3 streams";
}

TEST_F(DetailStreamsTest, ADriverGetsPreviewFramesAnsweringItsPoses) {
  auto ctx = context(editor_);
  auto drive = stub_->Drive(ctx.get());
  v1::DriveRequest r;
  r.set_session_id(id_);
  r.set_frame_format(v1::FRAME_FORMAT_CHUNKED);
  r.set_max_vertices(256);
  r.set_pose_id(7);
  r.add_indices(0);
  for (int k = 0; k < 3; ++k) r.add_positions(base_positions_[k] + 0.05f);
  ASSERT_TRUE(drive->Write(r));
  LevelClient client;
  v1::Frame f;
  std::uint64_t answered = 0;
  while (answered != 7) {
    ASSERT_TRUE(drive->Read(&f));
    client.apply(f, full_);
    if (!f.has_level()) answered = f.pose_id();
  }
  EXPECT_EQ(client.level, 256u);
  drive->WritesDone();
  while (drive->Read(&f)) {
  }
  EXPECT_TRUE(drive->Finish().ok());
}

TEST_F(DetailStreamsTest, BadBudgetsAndStreamsAreRefused) {
  // A level needs the chunked format.
  auto single = watch(512, v1::FRAME_FORMAT_SINGLE);
  v1::Frame f;
  EXPECT_FALSE(single->reader->Read(&f));
  const grpc::Status refused = single->reader->Finish();
  single->finished = true;
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(refused.error_message().find("FRAME_FORMAT_CHUNKED"), std::string::npos) << refused.error_message();

  auto level = watch(300);
  ASSERT_TRUE(level->read_until(0, full_));
  v1::SetDetailResponse answer;
  EXPECT_EQ(set_detail(level->client.stream_id, 0, &answer, viewer_).error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(set_detail(level->client.stream_id + 1, 512, &answer, viewer_).error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(set_detail(0, 512, &answer, viewer_).error_code(), grpc::StatusCode::NOT_FOUND);
  const grpc::Status bad_token = set_detail(level->client.stream_id, 512, &answer, "not-a-token");
  EXPECT_FALSE(bad_token.ok()) << "a level changed without a token";
  // The stream is unharmed and still at its level.
  const std::uint64_t bent = submit_bend(0.3, 1);
  ASSERT_TRUE(level->read_until(bent, full_));
  EXPECT_EQ(level->client.level, 256u);
}

}  // namespace
}  // namespace filigree
