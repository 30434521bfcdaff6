// Levels of detail in the C++ client library: DecodedLevel and the
// FrameDecoder's levels on their own, then Watcher and Driver streams with a
// vertex budget against a filigree-server child: the level a budget gets,
// level frames that sit where the full frame puts their vertices, and
// set_detail moving a live stream to another level.

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <functional>
#include <memory>
#include <numbers>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "codec/level_mesh_codec.h"
#include "filigree/client.h"
#include "support/server_process.h"
#include "support/test_meshes.h"

namespace filigree {
namespace {

// ---------------------------------------------------------------- no server

// A rest mesh of `n` vertices whose vertex i is at (i, 2i, 3i).
std::vector<float> numbered_rest(std::size_t n) {
  std::vector<float> rest(3 * n);
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t c = 0; c < 3; ++c) rest[3 * i + c] = static_cast<float>((c + 1) * i);
  return rest;
}

// Faces as a set of triangles, each from its smallest index on (its
// orientation kept): the codec may reorder faces and rotate their corners.
std::set<std::array<std::uint32_t, 3>> triangles(const std::vector<std::uint32_t>& faces) {
  std::set<std::array<std::uint32_t, 3>> out;
  for (std::size_t f = 0; f + 2 < faces.size(); f += 3) {
    std::array<std::uint32_t, 3> t = {faces[f], faces[f + 1], faces[f + 2]};
    std::rotate(t.begin(), std::min_element(t.begin(), t.end()), t.end());
    out.insert(t);
  }
  return out;
}

v1::DetailLevel level_message(const LevelMesh& mesh, std::uint32_t vertex_count, std::uint32_t face_count) {
  v1::DetailLevel level;
  level.set_vertex_count(vertex_count);
  level.set_face_count(face_count);
  level.set_mesh(encode_level_mesh(mesh));
  level.set_stream_id(77);
  return level;
}

TEST(DecodedLevel, GathersTheRestPositionsOfItsVertices) {
  const std::vector<float> rest = numbered_rest(10);
  const LevelMesh mesh{{1, 4, 6, 9}, {0, 1, 2, 0, 2, 3}};
  const DecodedLevel level = decode_level(level_message(mesh, 4, 2), rest);
  EXPECT_EQ(level.vertex_count, 4u);
  EXPECT_EQ(level.face_count, 2u);
  EXPECT_EQ(level.stream_id, 77u);
  EXPECT_FALSE(level.full_detail);
  EXPECT_EQ(level.original_ids, mesh.original_ids);
  EXPECT_EQ(triangles(level.faces), triangles(mesh.faces));
  ASSERT_EQ(level.rest_positions.size(), 12u);
  for (std::size_t i = 0; i < 4; ++i)
    for (std::size_t c = 0; c < 3; ++c)
      EXPECT_EQ(level.rest_positions[3 * i + c], rest[3 * mesh.original_ids[i] + c]) << "level vertex " << i;
}

TEST(DecodedLevel, TheFullMeshComesWithoutAMesh) {
  v1::DetailLevel full;
  full.set_vertex_count(10);
  full.set_face_count(16);
  full.set_stream_id(5);
  const DecodedLevel level = decode_level(full, numbered_rest(10));
  EXPECT_TRUE(level.full_detail);
  EXPECT_EQ(level.vertex_count, 10u);
  EXPECT_EQ(level.stream_id, 5u);
  EXPECT_TRUE(level.original_ids.empty());
  EXPECT_TRUE(level.faces.empty());
}

TEST(DecodedLevel, ALevelThatDoesNotFitTheMeshIsDataLoss) {
  const std::vector<float> rest = numbered_rest(10);
  const LevelMesh mesh{{1, 4, 6, 9}, {0, 1, 2, 0, 2, 3}};
  const auto code_of = [&](const v1::DetailLevel& level) {
    try {
      decode_level(level, rest);
    } catch (const ClientError& e) {
      return e.code();
    }
    return grpc::StatusCode::OK;
  };
  EXPECT_EQ(code_of(level_message(mesh, 5, 2)), grpc::StatusCode::DATA_LOSS);  // 4 ids for 5 vertices
  EXPECT_EQ(code_of(level_message(mesh, 4, 3)), grpc::StatusCode::DATA_LOSS);  // 2 faces, not 3
  EXPECT_EQ(code_of(level_message(mesh, 4, 2)), grpc::StatusCode::OK);
  v1::DetailLevel no_mesh;
  no_mesh.set_vertex_count(4);
  EXPECT_EQ(code_of(no_mesh), grpc::StatusCode::DATA_LOSS);  // only full detail omits the mesh
  EXPECT_EQ(code_of(level_message({{1, 4, 6, 12}, {0, 1, 2}}, 4, 1)), grpc::StatusCode::DATA_LOSS);  // id 12 ≥ 10
  v1::DetailLevel garbage = level_message(mesh, 4, 2);
  garbage.set_mesh("not draco");
  EXPECT_EQ(code_of(garbage), grpc::StatusCode::DATA_LOSS);
}

TEST(FrameDecoderLevels, FramesMustBeAtTheDecodersLevel) {
  FrameDecoder decoder(numbered_rest(10), 1);
  EXPECT_EQ(decoder.level(), nullptr);
  const auto code_of = [&](const v1::Frame& frame) {
    try {
      decoder.decode(frame);
    } catch (const ClientError& e) {
      return e.code();
    }
    return grpc::StatusCode::OK;
  };
  // A level message is set_level's, not a frame.
  v1::Frame starts;
  *starts.mutable_level() = level_message({{1, 4, 6, 9}, {0, 1, 2, 0, 2, 3}}, 4, 2);
  EXPECT_EQ(code_of(starts), grpc::StatusCode::INVALID_ARGUMENT);
  // A frame of 4 vertices at no level, then at the level of 4.
  v1::Frame frame;
  frame.set_version(3);
  frame.set_vertex_count(4);
  frame.set_level_vertices(4);
  EXPECT_EQ(code_of(frame), grpc::StatusCode::DATA_LOSS);
  const DecodedLevel& level = decoder.set_level(starts.level());
  EXPECT_EQ(level.vertex_count, 4u);
  ASSERT_NE(decoder.level(), nullptr);
  EXPECT_EQ(decoder.level()->original_ids, (std::vector<std::uint32_t>{1, 4, 6, 9}));
  // Single-format frames with no deltas (all zero): the level's rest positions.
  const DecodedFrame at_rest = decoder.decode(frame);
  EXPECT_EQ(at_rest.level, decoder.level());
  ASSERT_EQ(at_rest.vertex_count(), 4u);
  EXPECT_EQ(at_rest.positions, decoder.level()->rest_positions);
  // Another level's frame, a frame of the full mesh, a wrong vertex count.
  frame.set_level_vertices(8);
  EXPECT_EQ(code_of(frame), grpc::StatusCode::DATA_LOSS);
  frame.set_level_vertices(0);
  frame.set_vertex_count(10);
  EXPECT_EQ(code_of(frame), grpc::StatusCode::DATA_LOSS);
  frame.set_level_vertices(4);
  frame.set_vertex_count(5);
  EXPECT_EQ(code_of(frame), grpc::StatusCode::DATA_LOSS);
  // A level that does not fit keeps the decoder at its level.
  v1::DetailLevel bad = starts.level();
  bad.set_vertex_count(3);
  EXPECT_THROW(decoder.set_level(bad), ClientError);
  EXPECT_EQ(decoder.level()->vertex_count, 4u);
  // Full detail: frames of the whole mesh, level_vertices 0.
  v1::DetailLevel full;
  full.set_vertex_count(10);
  EXPECT_TRUE(decoder.set_level(full).full_detail);
  frame.set_level_vertices(0);
  frame.set_vertex_count(10);
  const DecodedFrame whole = decoder.decode(frame);
  EXPECT_EQ(whole.positions, decoder.rest_positions());
}

// ---------------------------------------------------------------- against a server

class DetailClientTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::path(::testing::TempDir()) /
           ("filigree_detail_client_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::remove_all(dir_);
    server_ = std::make_unique<test::ServerProcess>(FILIGREE_SERVER_BINARY,
                                                    std::vector<std::string>{"--data-dir", dir_.string()});
    client_ = std::make_unique<Client>(server_->address());
    v1::SessionOptions options;
    options.set_base_vertices(150);
    session_ = client_->create_session(test::file_bytes(test::shipped_path("bunny_small.obj")), "obj", options,
                                       "test_detail_client");
    n_ = session_.mesh.vertex_count();
    m_ = session_.mesh.base_vertex_count();
  }
  void TearDown() override {
    client_.reset();
    server_.reset();
    std::filesystem::remove_all(dir_);
  }

  // One stream's messages through a FrameDecoder, as an engine reads them.
  struct Reader {
    std::function<std::optional<v1::Frame>()> read;
    FrameDecoder decoder;
    std::optional<DecodedFrame> last;
    int levels = 0;  // level messages read

    // Reads until a frame whose version is at least `version` and (unless
    // 0) whose level has `vertices` vertices; false if the stream ends.
    bool read_until(std::uint64_t version, std::size_t vertices = 0) {
      while (!last || last->version < version || (vertices != 0 && last->vertex_count() != vertices)) {
        std::optional<v1::Frame> message = read();
        if (!message) return false;
        if (message->has_level()) {
          decoder.set_level(message->level());
          ++levels;
        } else {
          last = decoder.decode(*message);
        }
      }
      return true;
    }
  };
  Reader reader(Watcher& w) { return Reader{[&w] { return w.read(); }, FrameDecoder(session_.mesh.rest_positions, 1), std::nullopt, 0}; }
  Reader reader(Driver& d) { return Reader{[&d] { return d.read(); }, FrameDecoder(session_.mesh.rest_positions, 1), std::nullopt, 0}; }

  // The base bent by `degrees` over its longest axis.
  std::vector<float> bend(double degrees) const {
    const std::vector<float>& base = session_.mesh.base_positions;
    float lo[3] = {1e30f, 1e30f, 1e30f}, hi[3] = {-1e30f, -1e30f, -1e30f};
    for (std::size_t i = 0; i < base.size(); ++i)
      lo[i % 3] = std::min(lo[i % 3], base[i]), hi[i % 3] = std::max(hi[i % 3], base[i]);
    int a = 0;
    for (int c = 1; c < 3; ++c)
      if (hi[c] - lo[c] > hi[a] - lo[a]) a = c;
    const int b = (a + 1) % 3;
    const double mid = 0.5 * (lo[a] + hi[a]), half = 0.5 * (hi[a] - lo[a]), center_b = 0.5 * (lo[b] + hi[b]);
    std::vector<float> out = base;
    for (std::size_t v = 0; v < m_; ++v) {
      const double u = base[3 * v + a] - mid;
      if (u <= 0.0) continue;
      const double angle = degrees * std::numbers::pi / 180.0 * (u / half), db = base[3 * v + b] - center_b;
      out[3 * v + a] = float(mid + u * std::cos(angle) - db * std::sin(angle));
      out[3 * v + b] = float(center_b + u * std::sin(angle) + db * std::cos(angle));
    }
    return out;
  }

  // Every vertex of `level_frame` where `full_frame` (same version) has its
  // original vertex, within both frames' errors; and the pose moved them.
  void expect_at_full_positions(const DecodedFrame& level_frame, const DecodedFrame& full_frame) const {
    ASSERT_EQ(level_frame.version, full_frame.version);
    ASSERT_EQ(full_frame.vertex_count(), n_);
    const bool full = !level_frame.level || level_frame.level->full_detail;
    ASSERT_EQ(level_frame.vertex_count(), full ? n_ : level_frame.level->vertex_count);
    const double tolerance = double{level_frame.max_error} + double{full_frame.max_error} + 1e-6;
    double worst = 0.0, moved = 0.0;
    for (std::size_t i = 0; i < level_frame.vertex_count(); ++i) {
      const std::size_t id = full ? i : level_frame.level->original_ids[i];
      for (std::size_t c = 0; c < 3; ++c) {
        worst = std::max(worst, double(std::fabs(level_frame.positions[3 * i + c] - full_frame.positions[3 * id + c])));
        moved = std::max(moved, double(std::fabs(full_frame.positions[3 * id + c] - session_.mesh.rest_positions[3 * id + c])));
      }
    }
    EXPECT_LE(worst, tolerance) << "level vertices away from their place in the full frame";
    EXPECT_GT(moved, 100 * tolerance) << "the pose moved nothing: the comparison proves nothing";
  }

  // Drives `pose` on a stream of its own and returns the version of the frame answering it.
  std::uint64_t drive(const std::vector<float>& pose) {
    auto driver = client_->drive(session_.session_id, session_.editor_token, "full");
    Reader r = reader(*driver);
    EXPECT_TRUE(driver->send(1, pose));
    while (r.read_until(0) && r.last->pose_id < 1) r.last.reset();
    driver->cancel();
    driver->finish();
    EXPECT_TRUE(r.last) << "no frame answered the pose";
    return r.last ? r.last->version : 0;
  }

  // Reads `level` (at `vertices`, unless 0) and `full` until both are at one
  // version, at least `version`: a new level makes the session compute a
  // frame for it, so a later frame may follow the one a pose asked for.
  static void read_to_one_version(Reader& level, Reader& full, std::uint64_t version, std::size_t vertices = 0) {
    ASSERT_TRUE(level.read_until(version, vertices));
    ASSERT_TRUE(full.read_until(level.last->version));
    while (level.last->version != full.last->version) {
      if (level.last->version < full.last->version) ASSERT_TRUE(level.read_until(full.last->version, vertices));
      else ASSERT_TRUE(full.read_until(level.last->version));
    }
  }

  std::filesystem::path dir_;
  std::unique_ptr<test::ServerProcess> server_;
  std::unique_ptr<Client> client_;
  SessionHandle session_;
  std::size_t n_ = 0, m_ = 0;
};

TEST_F(DetailClientTest, AWatchersBudgetGetsItsLevelAndTheFullFramesPositions) {
  ASSERT_EQ(n_, 1839u);
  ASSERT_EQ(m_, 150u);
  // Budgets round down to a power of two; the base below its size, the
  // full mesh at or above it.
  const std::vector<std::pair<std::uint32_t, std::size_t>> cases = {
      {1, 150}, {200, 150}, {300, 256}, {1000, 512}, {1838, 1024}, {1839, 1839}, {100000, 1839}};
  std::vector<std::unique_ptr<Watcher>> watchers;
  std::vector<Reader> readers;
  for (const auto& [budget, expected] : cases)
    watchers.push_back(client_->watch(session_.session_id, session_.viewer_token, WatchOptions{.max_vertices = budget}));
  for (auto& w : watchers) readers.push_back(reader(*w));
  // Each starts with its level and the current frame at it.
  for (std::size_t i = 0; i < cases.size(); ++i) {
    SCOPED_TRACE("budget " + std::to_string(cases[i].first));
    ASSERT_TRUE(readers[i].read_until(0));
    EXPECT_EQ(readers[i].levels, 1);
    ASSERT_NE(readers[i].decoder.level(), nullptr);
    const DecodedLevel& level = *readers[i].decoder.level();
    EXPECT_EQ(level.vertex_count, cases[i].second);
    EXPECT_EQ(readers[i].last->vertex_count(), cases[i].second);
    EXPECT_EQ(level.full_detail, cases[i].second == n_);
    if (!level.full_detail) {
      EXPECT_EQ(level.original_ids.size(), cases[i].second);
      EXPECT_TRUE(std::adjacent_find(level.original_ids.begin(), level.original_ids.end(), std::greater_equal<>()) ==
                  level.original_ids.end())
          << "ids must ascend";
      EXPECT_EQ(level.faces.size(), 3u * level.face_count);
      ASSERT_FALSE(level.faces.empty());
      EXPECT_LT(*std::max_element(level.faces.begin(), level.faces.end()), level.vertex_count);
    }
  }
  auto full_watcher = client_->watch(session_.session_id, session_.viewer_token);
  Reader full = reader(*full_watcher);
  const std::uint64_t posed = drive(bend(50.0));
  for (std::size_t i = 0; i < cases.size(); ++i) {
    SCOPED_TRACE("budget " + std::to_string(cases[i].first));
    read_to_one_version(readers[i], full, posed);
    if (HasFatalFailure()) return;
    expect_at_full_positions(*readers[i].last, *full.last);
  }
  full_watcher->cancel();
  // A stream opened at full detail has no level to change.
  auto plain = client_->watch(session_.session_id, session_.viewer_token);
  try {
    plain->set_detail(512);
    ADD_FAILURE() << "set_detail on a full-detail stream";
  } catch (const ClientError& e) {
    EXPECT_EQ(e.code(), grpc::StatusCode::FAILED_PRECONDITION) << e.what();
  }
  for (auto& w : watchers) w->cancel();
}

TEST_F(DetailClientTest, SetDetailMovesALiveWatcherToAnotherLevel) {
  auto watcher = client_->watch(session_.session_id, session_.viewer_token, WatchOptions{.max_vertices = 300});
  Reader r = reader(*watcher);
  auto full_watcher = client_->watch(session_.session_id, session_.viewer_token);
  Reader full = reader(*full_watcher);
  // Before its level was read the stream's id is unknown.
  try {
    watcher->set_detail(1000);
    ADD_FAILURE() << "set_detail before the level was read";
  } catch (const ClientError& e) {
    EXPECT_EQ(e.code(), grpc::StatusCode::FAILED_PRECONDITION) << e.what();
  }
  ASSERT_TRUE(r.read_until(0));
  ASSERT_EQ(r.last->vertex_count(), 256u);
  try {
    watcher->set_detail(0);
    ADD_FAILURE() << "a budget of 0 vertices";
  } catch (const ClientError& e) {
    EXPECT_EQ(e.code(), grpc::StatusCode::INVALID_ARGUMENT) << e.what();
  }
  // Up: frames of the new level come without a pose, after its level.
  EXPECT_EQ(watcher->set_detail(1000), 512u);
  ASSERT_TRUE(r.read_until(0, 512));
  EXPECT_EQ(r.levels, 2);
  EXPECT_EQ(r.decoder.level()->vertex_count, 512u);
  read_to_one_version(r, full, drive(bend(30.0)), 512);
  if (HasFatalFailure()) return;
  expect_at_full_positions(*r.last, *full.last);
  // To full detail (the current frame again, at it), then to the base.
  EXPECT_EQ(watcher->set_detail(1u << 30), n_);
  read_to_one_version(r, full, full.last->version, n_);
  if (HasFatalFailure()) return;
  EXPECT_TRUE(r.decoder.level()->full_detail);
  expect_at_full_positions(*r.last, *full.last);
  EXPECT_EQ(watcher->set_detail(1), m_);
  read_to_one_version(r, full, drive(bend(-25.0)), m_);
  if (HasFatalFailure()) return;
  expect_at_full_positions(*r.last, *full.last);
  EXPECT_EQ(r.levels, 4);
  watcher->cancel();
  EXPECT_EQ(watcher->finish().error_code(), grpc::StatusCode::CANCELLED);
  full_watcher->cancel();
}

TEST_F(DetailClientTest, ADriverAtALevelGetsLevelFramesOfItsPoses) {
  auto driver = client_->drive(session_.session_id, session_.editor_token, "preview", DriveOptions{.max_vertices = 300});
  Reader r = reader(*driver);
  auto full_watcher = client_->watch(session_.session_id, session_.viewer_token);
  Reader full = reader(*full_watcher);
  ASSERT_TRUE(driver->send(1, bend(45.0)));
  while (r.read_until(0) && r.last->pose_id < 1) r.last.reset();
  ASSERT_TRUE(r.last);
  EXPECT_EQ(r.levels, 1);
  EXPECT_EQ(r.last->vertex_count(), 256u);
  read_to_one_version(r, full, r.last->version);
  if (HasFatalFailure()) return;
  expect_at_full_positions(*r.last, *full.last);
  // A driver changes its level too; its next pose's frame is at the new one.
  EXPECT_EQ(driver->set_detail(700), 512u);
  ASSERT_TRUE(driver->send(2, bend(20.0)));
  while (r.read_until(0, 512) && r.last->pose_id < 2) r.last.reset();
  ASSERT_TRUE(r.last);
  EXPECT_EQ(r.levels, 2);
  read_to_one_version(r, full, r.last->version, 512);
  if (HasFatalFailure()) return;
  expect_at_full_positions(*r.last, *full.last);
  driver->writes_done();
  EXPECT_TRUE(driver->finish().ok());
  full_watcher->cancel();
}

}  // namespace
}  // namespace filigree
