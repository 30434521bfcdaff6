// Working together through the C API (libfiligree.so): history, undo and
// redo with others' work kept, gestures as one entry, checkpoints, presence
// and the history's export, against a filigree-server child. Every state is
// read back from the server (the exported base pose is the merged pose).
//
// Like test_c_api, this process links libfiligree.so only: the C++ client
// cannot share a process with it (protobuf would register the contract twice).

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <initializer_list>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "filigree/filigree.h"
#include "support/server_process.h"
#include "support/test_meshes.h"

namespace {

using Clock = std::chrono::steady_clock;

std::string last_error() { return filigree_last_error(); }

// A string of any handle, through the size query and the copy.
template <class H>
std::string string_from(int (*get)(const H*, char*, size_t, size_t*), const H* handle) {
  size_t required = 0;
  EXPECT_EQ(get(handle, nullptr, 0, &required), FILIGREE_ERROR_BUFFER_TOO_SMALL);
  std::string s(required, '\0');
  EXPECT_EQ(get(handle, s.data(), s.size(), nullptr), FILIGREE_OK);
  s.resize(required ? required - 1 : 0);
  return s;
}

// The same of a handle's element `index` (an entry, a participant).
template <class H>
std::string string_from(int (*get)(const H*, size_t, char*, size_t, size_t*), const H* handle, size_t index) {
  size_t required = 0;
  EXPECT_EQ(get(handle, index, nullptr, 0, &required), FILIGREE_ERROR_BUFFER_TOO_SMALL);
  std::string s(required, '\0');
  EXPECT_EQ(get(handle, index, s.data(), s.size(), nullptr), FILIGREE_OK);
  s.resize(required ? required - 1 : 0);
  return s;
}

// A uint32 array of a history or presence handle's element `index`.
template <class H>
std::vector<uint32_t> array_from(int (*get)(const H*, size_t, uint32_t*, size_t, size_t*), const H* handle,
                                 size_t index) {
  size_t required = 0;
  const int rc = get(handle, index, nullptr, 0, &required);
  EXPECT_EQ(rc, required == 0 ? FILIGREE_OK : FILIGREE_ERROR_BUFFER_TOO_SMALL);
  std::vector<uint32_t> out(required);
  EXPECT_EQ(get(handle, index, out.data(), out.size(), nullptr), FILIGREE_OK);
  return out;
}

// One entry of a history read, with its strings and vertices.
struct Entry {
  filigree_history_entry info{};
  std::string author;
  std::vector<uint32_t> vertices;
};

struct Checkpoint {
  filigree_checkpoint info{};
  std::string name, author;
};

struct History {
  filigree_history_info info{};
  std::vector<Entry> entries;
  std::vector<Checkpoint> checkpoints;
};

class CApiHistory : public ::testing::Test {
 protected:
  void SetUp() override {
    data_dir_ = std::filesystem::path(::testing::TempDir()) /
                ("filigree_c_api_history_" + std::to_string(::getpid()) + "_" +
                 ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::remove_all(data_dir_);
    server_ = std::make_unique<filigree::test::ServerProcess>(
        FILIGREE_SERVER_BINARY, std::vector<std::string>{"--data-dir", data_dir_.string()});
    ASSERT_EQ(filigree_connect(server_->address().c_str(), nullptr, &client_), FILIGREE_OK) << last_error();
    const std::string bytes = filigree::test::file_bytes(filigree::test::shipped_path("bunny_small.obj"));
    filigree_session_options options{};
    options.base_vertices = 150;
    ASSERT_EQ(filigree_create_session(client_, bytes.data(), bytes.size(), "obj", &options, "test", &session_),
              FILIGREE_OK)
        << last_error();
    ASSERT_EQ(filigree_session_vertex_count(session_, &n_), FILIGREE_OK);
    ASSERT_EQ(filigree_session_base_vertex_count(session_, &m_), FILIGREE_OK);
    base_.resize(3 * m_);
    ASSERT_EQ(filigree_session_base_positions(session_, base_.data(), base_.size(), nullptr), FILIGREE_OK);
  }
  void TearDown() override {
    for (filigree_driver* d : drivers_) {
      filigree_driver_close(d);
      filigree_driver_free(d);
    }
    filigree_session_free(session_);
    filigree_client_free(client_);
    server_.reset();
    std::filesystem::remove_all(data_dir_);
  }

  filigree_driver* driver(const char* name) {
    filigree_driver* d = nullptr;
    EXPECT_EQ(filigree_driver_open(session_, nullptr, name, &d), FILIGREE_OK) << last_error();
    drivers_.push_back(d);
    return d;
  }

  // `d` moves base vertices `vertices` up by `dy` from rest in gesture
  // `gesture`, and waits until a frame includes the pose (it is merged, so in
  // the history).
  void move(filigree_driver* d, uint64_t gesture, std::initializer_list<uint32_t> vertices, float dy) {
    ASSERT_EQ(filigree_driver_set_gesture(d, gesture), FILIGREE_OK);
    std::vector<uint32_t> indices(vertices);
    std::vector<float> positions;
    for (uint32_t v : indices) positions.insert(positions.end(), {base_[3 * v], base_[3 * v + 1] + dy, base_[3 * v + 2]});
    const uint64_t pose = ++pose_ids_;
    ASSERT_EQ(filigree_driver_send_partial(d, pose, indices.data(), indices.size(), positions.data(), positions.size()),
              FILIGREE_OK)
        << filigree_driver_last_error(d);
    ASSERT_EQ(filigree_driver_wait_for_pose(d, pose, 30000), FILIGREE_OK) << filigree_driver_last_error(d);
    std::vector<float> frame(3 * n_);
    ASSERT_EQ(filigree_driver_poll(d, frame.data(), frame.size(), nullptr, nullptr, nullptr), FILIGREE_OK);
  }

  History history(uint32_t newest = 0) {
    History out;
    filigree_history* h = nullptr;
    EXPECT_EQ(filigree_history_read(session_, nullptr, newest, &h), FILIGREE_OK) << last_error();
    if (!h) return out;
    EXPECT_EQ(filigree_history_info_get(h, &out.info), FILIGREE_OK);
    for (size_t i = 0; i < out.info.entry_count; ++i) {
      Entry e;
      EXPECT_EQ(filigree_history_entry_get(h, i, &e.info), FILIGREE_OK);
      e.author = string_from(filigree_history_entry_author, static_cast<const filigree_history*>(h), i);
      e.vertices = array_from(filigree_history_entry_vertices, static_cast<const filigree_history*>(h), i);
      out.entries.push_back(std::move(e));
    }
    for (size_t i = 0; i < out.info.checkpoint_count; ++i) {
      Checkpoint c;
      EXPECT_EQ(filigree_history_checkpoint_get(h, i, &c.info), FILIGREE_OK);
      c.name = string_from(filigree_history_checkpoint_name, static_cast<const filigree_history*>(h), i);
      c.author = string_from(filigree_history_checkpoint_author, static_cast<const filigree_history*>(h), i);
      out.checkpoints.push_back(std::move(c));
    }
    filigree_history_entry beyond{};
    EXPECT_EQ(filigree_history_entry_get(h, out.info.entry_count, &beyond), FILIGREE_OUT_OF_RANGE);
    EXPECT_EQ(filigree_history_free(h), FILIGREE_OK);
    return out;
  }

  // The merged pose now: the exported state after the newest entry.
  std::vector<float> current_pose() {
    const History h = history(1);
    EXPECT_EQ(h.entries.size(), 1u);
    if (h.entries.empty()) return {};
    const uint64_t newest = h.entries.back().info.seq;
    filigree_history_export* e = nullptr;
    EXPECT_EQ(filigree_export_history(session_, nullptr, newest, newest, &e), FILIGREE_OK) << last_error();
    std::vector<float> positions(3 * n_), pose(3 * m_);
    filigree_history_state state{};
    EXPECT_EQ(filigree_history_export_next(e, positions.data(), positions.size(), nullptr, &state), FILIGREE_OK)
        << filigree_history_export_last_error(e);
    EXPECT_EQ(state.entry, newest);
    EXPECT_EQ(filigree_history_export_base_pose(e, pose.data(), pose.size(), nullptr), FILIGREE_OK);
    EXPECT_EQ(filigree_history_export_next(e, positions.data(), positions.size(), nullptr, nullptr),
              FILIGREE_ERROR_STREAM_ENDED);
    EXPECT_EQ(filigree_history_export_free(e), FILIGREE_OK);
    return pose;
  }

  // Each base vertex's height above rest now.
  std::vector<float> heights() {
    const std::vector<float> pose = current_pose();
    std::vector<float> out(m_, 0.0f);
    for (size_t v = 0; v < m_ && 3 * v + 1 < pose.size(); ++v) out[v] = pose[3 * v + 1] - base_[3 * v + 1];
    return out;
  }
  std::vector<float> expect(std::initializer_list<std::pair<uint32_t, float>> set) const {
    std::vector<float> out(m_, 0.0f);
    for (const auto& [v, h] : set) out[v] = h;
    return out;
  }
  static void expect_heights(const std::vector<float>& got, const std::vector<float>& want) {
    ASSERT_EQ(got.size(), want.size());
    for (size_t v = 0; v < got.size(); ++v) EXPECT_NEAR(got[v], want[v], 1e-6) << "base vertex " << v;
  }

  std::string edit_conflicts() {
    return string_from(filigree_session_edit_conflicts, static_cast<const filigree_session*>(session_));
  }

  std::filesystem::path data_dir_;
  std::unique_ptr<filigree::test::ServerProcess> server_;
  filigree_client* client_ = nullptr;
  filigree_session* session_ = nullptr;
  std::vector<filigree_driver*> drivers_;
  size_t n_ = 0, m_ = 0;
  std::vector<float> base_;
  uint64_t pose_ids_ = 0;
};

TEST_F(CApiHistory, UndoKeepsOthersLaterWorkAndRedoBringsItBack) {
  filigree_driver* ana = driver("ana");
  filigree_driver* ben = driver("ben");
  // Ana's drag of 1–2 (two poses of gesture 11), Ben on 3, Ben over Ana's 2.
  move(ana, 11, {1, 2}, 0.01f);
  move(ana, 11, {1, 2}, 0.03f);
  move(ben, 21, {3}, 0.02f);
  move(ben, 22, {2}, 0.05f);
  const History h = history();
  ASSERT_EQ(h.entries.size(), 3u) << "Ana's two poses of gesture 11 are one entry";
  EXPECT_EQ(h.entries[0].author, "ana");
  EXPECT_EQ(h.entries[0].info.kind, FILIGREE_HISTORY_POSE);
  EXPECT_EQ(h.entries[0].info.gesture_id, 11u);
  EXPECT_EQ(h.entries[0].vertices, (std::vector<uint32_t>{1, 2}));
  EXPECT_EQ(h.entries[0].info.vertex_count, 2u);
  EXPECT_EQ(h.entries[2].author, "ben");
  EXPECT_EQ(h.entries[2].info.gesture_id, 22u);
  EXPECT_EQ(h.info.entry_count, 3u);
  expect_heights(heights(), expect({{1, 0.03f}, {2, 0.05f}, {3, 0.02f}}));

  // Ana's undo: vertex 1 goes back; vertex 2 keeps Ben's later change.
  filigree_edit_outcome o{};
  ASSERT_EQ(filigree_undo(session_, nullptr, "ana", 0, &o), FILIGREE_OK) << last_error();
  EXPECT_EQ(o.result, FILIGREE_EDIT_PARTIAL);
  EXPECT_EQ(o.entry, h.entries[0].info.seq);
  EXPECT_NE(o.recorded, 0u);
  EXPECT_EQ(o.conflict_count, 1u);
  EXPECT_EQ(o.conflict_vertex_count, 1u);
  EXPECT_GT(o.accepted_at_version, 0u);
  EXPECT_EQ(edit_conflicts(), "ben\t" + std::to_string(h.entries[2].info.seq) + "\t2\n");
  EXPECT_FALSE(string_from(filigree_session_edit_message, static_cast<const filigree_session*>(session_)).empty());
  expect_heights(heights(), expect({{2, 0.05f}, {3, 0.02f}}));
  const History undone = history();
  ASSERT_EQ(undone.entries.size(), 4u);
  EXPECT_EQ(undone.entries[0].info.undone, 1);
  EXPECT_EQ(undone.entries[3].info.kind, FILIGREE_HISTORY_UNDO);
  EXPECT_EQ(undone.entries[3].info.target, h.entries[0].info.seq);

  // Her redo brings vertex 1 back (vertex 2 was not hers to restore); a second has nothing.
  ASSERT_EQ(filigree_redo(session_, nullptr, "ana", 0, &o), FILIGREE_OK) << last_error();
  EXPECT_EQ(o.result, FILIGREE_EDIT_DONE);
  EXPECT_EQ(edit_conflicts(), "");
  expect_heights(heights(), expect({{1, 0.03f}, {2, 0.05f}, {3, 0.02f}}));
  ASSERT_EQ(filigree_redo(session_, nullptr, "ana", 0, &o), FILIGREE_OK);
  EXPECT_EQ(o.result, FILIGREE_EDIT_NOTHING);
  EXPECT_EQ(o.recorded, 0u);
  // NULL outcome is allowed; Ben's undo takes back his vertex-2 change only.
  ASSERT_EQ(filigree_undo(session_, nullptr, "ben", 0, nullptr), FILIGREE_OK);
  expect_heights(heights(), expect({{1, 0.03f}, {2, 0.03f}, {3, 0.02f}}));
}

TEST_F(CApiHistory, AnUndoOfVerticesOthersChangedSinceChangesNothingUnlessForced) {
  filigree_driver* ana = driver("ana");
  filigree_driver* ben = driver("ben");
  move(ana, 1, {7}, 0.01f);
  move(ben, 2, {7}, 0.02f);
  filigree_edit_outcome o{};
  ASSERT_EQ(filigree_undo(session_, nullptr, "ana", 0, &o), FILIGREE_OK);
  EXPECT_EQ(o.result, FILIGREE_EDIT_CONFLICT);
  EXPECT_EQ(o.recorded, 0u);
  EXPECT_EQ(edit_conflicts().rfind("ben\t", 0), 0u) << edit_conflicts();
  expect_heights(heights(), expect({{7, 0.02f}}));
  ASSERT_EQ(filigree_undo(session_, nullptr, "ana", /*force=*/1, &o), FILIGREE_OK);
  EXPECT_EQ(o.result, FILIGREE_EDIT_DONE);
  expect_heights(heights(), expect({}));
  // A viewer's token may not undo.
  const std::string viewer = string_from(filigree_session_viewer_token, static_cast<const filigree_session*>(session_));
  EXPECT_EQ(filigree_undo(session_, viewer.c_str(), "ana", 0, &o), FILIGREE_PERMISSION_DENIED);
  EXPECT_NE(std::string(filigree_session_last_error(session_)).find("filigree_undo"), std::string::npos);
}

TEST_F(CApiHistory, AGestureIsOneEntryAndUndoesAsOne) {
  filigree_driver* d = driver("dragger");
  // Four poses of gesture 5 on vertex 9, then gesture 6 on vertex 10, sent
  // well within 0.5 s: without the ids they would all be one entry.
  for (int k = 1; k <= 4; ++k) move(d, 5, {9}, 0.01f * static_cast<float>(k));
  move(d, 6, {10}, 0.02f);
  const History h = history();
  ASSERT_EQ(h.entries.size(), 2u);
  EXPECT_EQ(h.entries[0].info.gesture_id, 5u);
  EXPECT_EQ(h.entries[1].info.gesture_id, 6u);
  EXPECT_EQ(h.entries[0].vertices, (std::vector<uint32_t>{9}));
  filigree_edit_outcome o{};
  ASSERT_EQ(filigree_undo(session_, nullptr, "dragger", 0, &o), FILIGREE_OK);
  EXPECT_EQ(o.entry, h.entries[1].info.seq);
  expect_heights(heights(), expect({{9, 0.04f}}));
  ASSERT_EQ(filigree_undo(session_, nullptr, "dragger", 0, &o), FILIGREE_OK);
  EXPECT_EQ(o.entry, h.entries[0].info.seq);
  expect_heights(heights(), expect({}));  // the whole drag, not its last pose

  // Handles: two calls of one gesture are one entry.
  const uint32_t vertex = 5;
  std::vector<float> rest(3 * n_);
  ASSERT_EQ(filigree_session_rest_positions(session_, rest.data(), rest.size(), nullptr), FILIGREE_OK);
  for (float dy : {0.01f, 0.02f}) {
    const float target[3] = {rest[3 * vertex], rest[3 * vertex + 1] + dy, rest[3 * vertex + 2]};
    uint32_t total = 0;
    ASSERT_EQ(filigree_set_handles_in_gesture(session_, nullptr, "pinner", 77, &vertex, 1, target, 3, &total),
              FILIGREE_OK)
        << last_error();
    EXPECT_EQ(total, 1u);
  }
  const History after = history();
  std::vector<const Entry*> handles;
  for (const Entry& e : after.entries)
    if (e.info.kind == FILIGREE_HISTORY_HANDLES) handles.push_back(&e);
  ASSERT_EQ(handles.size(), 1u);
  EXPECT_EQ(handles[0]->author, "pinner");
  EXPECT_EQ(handles[0]->info.gesture_id, 77u);
}

TEST_F(CApiHistory, CheckpointsAreMadeListedDiffedRestoredAndTheRestoreUndoes) {
  filigree_driver* ana = driver("ana");
  filigree_driver* ben = driver("ben");
  move(ana, 1, {1}, 0.01f);
  filigree_checkpoint made{};
  ASSERT_EQ(filigree_create_checkpoint(session_, nullptr, "before the review", "ana", &made), FILIGREE_OK)
      << last_error();
  EXPECT_GT(made.id, 0u);
  EXPECT_EQ(made.after_entry, history().entries.back().info.seq);
  move(ben, 2, {2, 3}, 0.02f);

  filigree_checkpoint_diff diff{};
  size_t required = 0;
  // The numbers alone, then the vertices by the buffer rules.
  ASSERT_EQ(filigree_diff_checkpoint(session_, nullptr, made.id, &diff, nullptr, 0, &required), FILIGREE_OK)
      << last_error();
  EXPECT_EQ(diff.checkpoint, made.id);
  EXPECT_EQ(diff.vertex_count, 2u);
  EXPECT_EQ(required, 2u);
  EXPECT_NEAR(diff.max_distance, 0.02, 1e-6);
  EXPECT_EQ(diff.threshold_differs, 0);
  uint32_t one = 0;
  EXPECT_EQ(filigree_diff_checkpoint(session_, nullptr, made.id, &diff, &one, 1, &required),
            FILIGREE_ERROR_BUFFER_TOO_SMALL);
  std::vector<uint32_t> differ(2);
  ASSERT_EQ(filigree_diff_checkpoint(session_, nullptr, made.id, &diff, differ.data(), differ.size(), nullptr),
            FILIGREE_OK);
  EXPECT_EQ(differ, (std::vector<uint32_t>{2, 3}));

  filigree_edit_outcome o{};
  ASSERT_EQ(filigree_restore_checkpoint(session_, nullptr, made.id, "cleo", &o), FILIGREE_OK) << last_error();
  EXPECT_EQ(o.result, FILIGREE_EDIT_DONE);
  expect_heights(heights(), expect({{1, 0.01f}}));
  ASSERT_EQ(filigree_diff_checkpoint(session_, nullptr, made.id, &diff, nullptr, 0, nullptr), FILIGREE_OK);
  EXPECT_EQ(diff.vertex_count, 0u);

  const History h = history();
  ASSERT_EQ(h.checkpoints.size(), 1u);
  EXPECT_EQ(h.checkpoints[0].info.id, made.id);
  EXPECT_EQ(h.checkpoints[0].name, "before the review");
  EXPECT_EQ(h.checkpoints[0].author, "ana");
  EXPECT_EQ(h.entries.back().info.kind, FILIGREE_HISTORY_RESTORE);
  EXPECT_EQ(h.entries.back().info.target, made.id);
  EXPECT_EQ(h.entries.back().author, "cleo");

  // The restore is Cleo's entry: her undo takes it back.
  ASSERT_EQ(filigree_undo(session_, nullptr, "cleo", 0, &o), FILIGREE_OK);
  EXPECT_EQ(o.result, FILIGREE_EDIT_DONE);
  expect_heights(heights(), expect({{1, 0.01f}, {2, 0.02f}, {3, 0.02f}}));

  EXPECT_EQ(filigree_restore_checkpoint(session_, nullptr, made.id + 100, "cleo", &o), FILIGREE_NOT_FOUND);
  EXPECT_EQ(filigree_create_checkpoint(session_, nullptr, "", "ana", &made), FILIGREE_INVALID_ARGUMENT);
  EXPECT_EQ(filigree_create_checkpoint(session_, nullptr, nullptr, "ana", &made), FILIGREE_ERROR_NULL_ARGUMENT);
  EXPECT_EQ(filigree_diff_checkpoint(session_, nullptr, made.id, nullptr, nullptr, 0, nullptr),
            FILIGREE_ERROR_NULL_ARGUMENT);
}

// A participant of a polled presence, by name.
struct Participant {
  filigree_participant info{};
  std::vector<uint32_t> touching;
};

std::vector<std::pair<std::string, Participant>> participants(const filigree_presence* p) {
  size_t count = 0;
  EXPECT_EQ(filigree_presence_participant_count(p, &count), FILIGREE_OK);
  std::vector<std::pair<std::string, Participant>> out;
  for (size_t i = 0; i < count; ++i) {
    Participant q;
    EXPECT_EQ(filigree_presence_participant_get(p, i, &q.info), FILIGREE_OK);
    q.touching = array_from(filigree_presence_participant_touching, p, i);
    out.emplace_back(string_from(filigree_presence_participant_name, p, i), std::move(q));
  }
  return out;
}

// Polls `p` until `ready` holds for a presence (30 s at most).
template <class Ready>
bool poll_until(filigree_presence* p, Ready&& ready) {
  const auto deadline = Clock::now() + std::chrono::seconds(30);
  while (Clock::now() < deadline) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now());
    const int rc = filigree_presence_wait(p, std::max<int64_t>(left.count(), 0));
    if (rc == FILIGREE_DEADLINE_EXCEEDED) break;
    EXPECT_EQ(rc, FILIGREE_OK) << filigree_presence_last_error(p);
    if (rc != FILIGREE_OK) return false;
    int updated = 0;
    uint64_t version = 0;
    EXPECT_EQ(filigree_presence_poll(p, &version, &updated), FILIGREE_OK);
    EXPECT_EQ(updated, 1);
    if (ready(participants(p))) return true;
  }
  return false;
}

const Participant* find(const std::vector<std::pair<std::string, Participant>>& all, const std::string& name) {
  for (const auto& [n, q] : all)
    if (n == name) return &q;
  return nullptr;
}

TEST_F(CApiHistory, PresenceShowsWhoIsHereTheirPointersAndWhatTheyTouch) {
  filigree_presence* p = nullptr;
  ASSERT_EQ(filigree_presence_open(session_, nullptr, "ana", &p), FILIGREE_OK) << last_error();
  EXPECT_TRUE(poll_until(p, [](const auto& all) { return find(all, "ana") != nullptr; })) << "ana listed";

  const float pointer[3] = {0.5f, 0.25f, -0.125f};
  ASSERT_EQ(filigree_set_presence(session_, nullptr, "ana", pointer, 12), FILIGREE_OK) << last_error();
  EXPECT_TRUE(poll_until(p, [&](const auto& all) {
    const Participant* ana = find(all, "ana");
    return ana && ana->info.has_pointer && ana->info.pointer_vertex == 12 && ana->info.pointer[0] == 0.5f &&
           ana->info.pointer[1] == 0.25f && ana->info.pointer[2] == -0.125f;
  })) << "ana's pointer";

  filigree_driver* cleo = driver("cleo");
  move(cleo, 3, {4, 5}, 0.01f);
  EXPECT_TRUE(poll_until(p, [](const auto& all) {
    const Participant* c = find(all, "cleo");
    return c && c->touching == std::vector<uint32_t>{4, 5};
  })) << "cleo touching 4 and 5";
  const auto all = participants(p);
  const Participant* c = find(all, "cleo");
  ASSERT_NE(c, nullptr);
  EXPECT_EQ(c->info.role, 1) << "an editor";
  // "#rrggbb" as 0xRRGGBB: the palette colour of the name's FNV-1a hash.
  constexpr uint32_t kPalette[] = {0xe6194b, 0x3cb44b, 0x4363d8, 0xf58231, 0x911eb4, 0xbfef45, 0xf032e6, 0x9a6324};
  uint32_t hash = 2166136261u;
  for (unsigned char ch : std::string("cleo")) hash = (hash ^ ch) * 16777619u;
  EXPECT_EQ(c->info.colour, kPalette[hash % 8]);

  ASSERT_EQ(filigree_set_presence(session_, nullptr, "ana", nullptr, 0), FILIGREE_OK);
  EXPECT_TRUE(poll_until(p, [](const auto& all) {
    const Participant* ana = find(all, "ana");
    return ana && !ana->info.has_pointer;
  })) << "ana's pointer cleared";

  filigree_participant none{};
  EXPECT_EQ(filigree_presence_participant_get(p, 1000, &none), FILIGREE_OUT_OF_RANGE);
  const float nan_pointer[3] = {std::nanf(""), 0.0f, 0.0f};
  EXPECT_EQ(filigree_set_presence(session_, nullptr, "ana", nan_pointer, 0), FILIGREE_INVALID_ARGUMENT);
  EXPECT_EQ(filigree_presence_close(p), FILIGREE_OK) << filigree_presence_last_error(p);
  int updated = 0;
  EXPECT_EQ(filigree_presence_poll(p, nullptr, &updated), FILIGREE_ERROR_STREAM_ENDED);
  EXPECT_EQ(filigree_presence_free(p), FILIGREE_OK);
  EXPECT_EQ(filigree_presence_poll(p, nullptr, &updated), FILIGREE_ERROR_INVALID_HANDLE);
}

TEST_F(CApiHistory, TheExportGivesTheStateAfterEachEntryEndingAtTheCurrentFrame) {
  filigree_driver* ana = driver("ana");
  filigree_driver* ben = driver("ben");
  move(ana, 1, {1, 2, 3}, 0.05f);
  move(ben, 2, {10}, -0.04f);
  const History h = history();
  ASSERT_EQ(h.entries.size(), 2u);

  // The current frame, from a watcher: the first frame past the newest entry.
  filigree_watcher* watcher = nullptr;
  ASSERT_EQ(filigree_watcher_open(session_, nullptr, 0, nullptr, nullptr, &watcher), FILIGREE_OK);
  std::vector<float> current(3 * n_);
  filigree_frame_info frame{};
  for (uint64_t version = 0; version <= h.entries.back().info.version;) {
    ASSERT_EQ(filigree_watcher_wait_frame(watcher, 30000), FILIGREE_OK) << filigree_watcher_last_error(watcher);
    ASSERT_EQ(filigree_watcher_poll(watcher, current.data(), current.size(), &version, nullptr, nullptr), FILIGREE_OK);
  }
  ASSERT_EQ(filigree_watcher_frame_info(watcher, &frame), FILIGREE_OK);
  EXPECT_EQ(filigree_watcher_close(watcher), FILIGREE_OK);
  filigree_watcher_free(watcher);

  filigree_history_export* e = nullptr;
  ASSERT_EQ(filigree_export_history(session_, nullptr, 0, 0, &e), FILIGREE_OK) << last_error();
  size_t required = 0;
  EXPECT_EQ(filigree_history_export_next(e, nullptr, 0, &required, nullptr), FILIGREE_ERROR_BUFFER_TOO_SMALL);
  EXPECT_EQ(required, 3 * n_);
  std::vector<std::vector<float>> states, poses;
  std::vector<std::string> authors;
  std::vector<filigree_history_state> infos;
  while (true) {
    std::vector<float> positions(3 * n_), pose(3 * m_);
    filigree_history_state state{};
    const int rc = filigree_history_export_next(e, positions.data(), positions.size(), nullptr, &state);
    if (rc == FILIGREE_ERROR_STREAM_ENDED) break;
    ASSERT_EQ(rc, FILIGREE_OK) << filigree_history_export_last_error(e);
    ASSERT_EQ(filigree_history_export_base_pose(e, pose.data(), pose.size(), nullptr), FILIGREE_OK);
    authors.push_back(string_from(filigree_history_export_author, static_cast<const filigree_history_export*>(e)));
    states.push_back(std::move(positions));
    poses.push_back(std::move(pose));
    infos.push_back(state);
  }
  EXPECT_EQ(filigree_history_export_close(e), FILIGREE_OK);
  EXPECT_EQ(filigree_history_export_free(e), FILIGREE_OK);

  ASSERT_EQ(states.size(), h.entries.size());
  EXPECT_EQ(authors, (std::vector<std::string>{"ana", "ben"}));
  EXPECT_EQ(infos[0].entry, h.entries[0].info.seq);
  EXPECT_EQ(infos[1].entry, h.entries[1].info.seq);
  EXPECT_EQ(infos[1].version, h.entries[1].info.version);
  // The first state holds Ana's change only.
  EXPECT_NEAR(poses[0][3 * 1 + 1], base_[3 * 1 + 1] + 0.05f, 1e-6);
  EXPECT_NEAR(poses[0][3 * 10 + 1], base_[3 * 10 + 1], 1e-7);
  EXPECT_NEAR(poses[1][3 * 10 + 1], base_[3 * 10 + 1] - 0.04f, 1e-6);
  // The last state is the frame the session sent for it, within both errors.
  std::vector<float> rest(3 * n_);
  ASSERT_EQ(filigree_session_rest_positions(session_, rest.data(), rest.size(), nullptr), FILIGREE_OK);
  double worst = 0.0, largest = 0.0;
  for (size_t i = 0; i < current.size(); ++i) {
    worst = std::max(worst, std::abs(double(states[1][i]) - double(current[i])));
    largest = std::max(largest, std::abs(double(current[i]) - double(rest[i])));
  }
  EXPECT_LE(worst, double(infos[1].max_error) + double(frame.max_error) + 1e-6);
  EXPECT_GT(largest, 0.01);

  // A range the server refuses ends the stream with why.
  ASSERT_EQ(filigree_export_history(session_, nullptr, 5, 2, &e), FILIGREE_OK);
  std::vector<float> positions(3 * n_);
  EXPECT_EQ(filigree_history_export_next(e, positions.data(), positions.size(), nullptr, nullptr),
            FILIGREE_INVALID_ARGUMENT);
  EXPECT_NE(std::string(filigree_history_export_last_error(e)).find("to_entry"), std::string::npos)
      << filigree_history_export_last_error(e);
  EXPECT_EQ(filigree_history_export_close(e), FILIGREE_INVALID_ARGUMENT);
  EXPECT_EQ(filigree_history_export_free(e), FILIGREE_OK);
  // Closing early cancels what is left: a normal end.
  ASSERT_EQ(filigree_export_history(session_, nullptr, 0, 0, &e), FILIGREE_OK);
  EXPECT_EQ(filigree_history_export_close(e), FILIGREE_OK);
  EXPECT_EQ(filigree_history_export_next(e, positions.data(), positions.size(), nullptr, nullptr),
            FILIGREE_ERROR_STREAM_ENDED);
  EXPECT_EQ(filigree_history_export_free(e), FILIGREE_OK);
}

TEST(CApiHistoryHandles, BadHandlesAreRefused) {
  filigree_history_info info{};
  filigree_edit_outcome o{};
  int updated = 0;
  EXPECT_EQ(filigree_history_info_get(nullptr, &info), FILIGREE_ERROR_INVALID_HANDLE);
  EXPECT_EQ(filigree_undo(nullptr, nullptr, "a", 0, &o), FILIGREE_ERROR_INVALID_HANDLE);
  EXPECT_EQ(filigree_presence_poll(nullptr, nullptr, &updated), FILIGREE_ERROR_INVALID_HANDLE);
  EXPECT_EQ(filigree_history_export_next(nullptr, nullptr, 0, nullptr, nullptr), FILIGREE_ERROR_INVALID_HANDLE);
  EXPECT_EQ(filigree_driver_set_gesture(nullptr, 1), FILIGREE_ERROR_INVALID_HANDLE);
  EXPECT_EQ(filigree_history_free(nullptr), FILIGREE_OK);
  EXPECT_EQ(filigree_presence_free(nullptr), FILIGREE_OK);
  EXPECT_EQ(filigree_history_export_free(nullptr), FILIGREE_OK);
  EXPECT_GT(std::strlen(filigree_history_last_error(nullptr)), 0u);
  EXPECT_GT(std::strlen(filigree_presence_last_error(nullptr)), 0u);
  EXPECT_GT(std::strlen(filigree_history_export_last_error(nullptr)), 0u);
}

}  // namespace
