// The edit history's model: per-author undo and redo that leave the others'
// later work alone, conflicts reported with who and what, gestures as one
// entry, bounds, checkpoints, and a round trip through its persisted form.

#include <gtest/gtest.h>

#include <vector>

#include "server/edit_history.h"

namespace filigree::server {
namespace {

constexpr std::size_t kBase = 6;

// A session's side: the merged pose, changed through the history like the
// session does (record, then write).
struct Editing {
  EditHistory history{kBase, HistoryLimits{}};
  std::vector<float> pose = std::vector<float>(3 * kBase, 0.0f);
  double now = 1000.0;
  std::uint64_t version = 0;

  // `author` moves `vertices` to x = value (a pose of one gesture).
  void move(const std::string& author, std::vector<std::uint32_t> vertices, float value, std::uint64_t gesture = 0) {
    std::vector<float> values;  // 3 per index
    for (std::uint32_t v : vertices) values.insert(values.end(), {value, pose[3 * v + 1], pose[3 * v + 2]});
    history.record_pose({author, gesture, now, ++version}, v1::HistoryEntry::KIND_POSE, vertices, pose, values);
    for (std::size_t i = 0; i < vertices.size(); ++i) pose[3 * vertices[i]] = value;
    now += 1.0;  // past the pause: a new entry unless a gesture id joins them
  }
  HistoryOutcome undo(const std::string& author, bool force = false) {
    return history.undo({author, 0, now += 1.0, ++version}, force, pose, 0.0);
  }
  HistoryOutcome redo(const std::string& author) { return history.redo({author, 0, now += 1.0, ++version}, false, pose, 0.0); }
  std::vector<float> xs() const {
    std::vector<float> out;
    for (std::size_t v = 0; v < kBase; ++v) out.push_back(pose[3 * v]);
    return out;
  }
};

TEST(EditHistory, EachAuthorUndoesOnlyTheirOwnAndKeepsTheOthersWork) {
  Editing e;
  e.move("ana", {0, 1}, 1.0f);
  e.move("ben", {2, 3}, 2.0f);
  e.move("cleo", {4}, 3.0f);
  e.move("ana", {5}, 4.0f);
  ASSERT_EQ(e.xs(), (std::vector<float>{1, 1, 2, 2, 3, 4}));
  // Ben's undo: his vertices back to rest, everyone else's work stays.
  HistoryOutcome o = e.undo("ben");
  EXPECT_EQ(o.answer.outcome(), v1::UndoResponse::OUTCOME_DONE);
  EXPECT_EQ(e.xs(), (std::vector<float>{1, 1, 0, 0, 3, 4}));
  // Ana's two undos take her latest change first.
  e.undo("ana");
  EXPECT_EQ(e.xs(), (std::vector<float>{1, 1, 0, 0, 3, 0}));
  e.undo("ana");
  EXPECT_EQ(e.xs(), (std::vector<float>{0, 0, 0, 0, 3, 0}));
  EXPECT_EQ(e.undo("ana").answer.outcome(), v1::UndoResponse::OUTCOME_NOTHING);
  // Redo in the other order.
  EXPECT_EQ(e.redo("ana").answer.outcome(), v1::UndoResponse::OUTCOME_DONE);
  EXPECT_EQ(e.xs(), (std::vector<float>{1, 1, 0, 0, 3, 0}));
  e.redo("ana");
  EXPECT_EQ(e.xs(), (std::vector<float>{1, 1, 0, 0, 3, 4}));
  EXPECT_EQ(e.redo("ana").answer.outcome(), v1::UndoResponse::OUTCOME_NOTHING);
}

TEST(EditHistory, AnUndoOfVerticesSomeoneChangedSinceReportsTheConflict) {
  Editing e;
  e.move("ana", {0, 1, 2}, 1.0f);
  e.move("ben", {1}, 5.0f);  // over one of Ana's
  HistoryOutcome o = e.undo("ana");
  // Ana's vertices 0 and 2 go back; vertex 1 keeps Ben's value, and the answer says so.
  EXPECT_EQ(o.answer.outcome(), v1::UndoResponse::OUTCOME_PARTIAL);
  EXPECT_EQ(e.xs(), (std::vector<float>{0, 5, 0, 0, 0, 0}));
  ASSERT_EQ(o.answer.conflicts_size(), 1);
  EXPECT_EQ(o.answer.conflicts(0).author(), "ben");
  EXPECT_EQ(o.answer.conflicts(0).base_vertices_size(), 1);
  EXPECT_EQ(o.answer.conflicts(0).base_vertices(0), 1u);
  // Ben's undo then restores what his change found there: Ana's value.
  e.undo("ben");
  EXPECT_EQ(e.xs(), (std::vector<float>{0, 1, 0, 0, 0, 0}));
}

TEST(EditHistory, AnUndoOfOnlyConflictingVerticesChangesNothingUnlessForced) {
  Editing e;
  e.move("ana", {3}, 1.0f);
  e.move("cleo", {3}, 7.0f);
  HistoryOutcome o = e.undo("ana");
  EXPECT_EQ(o.answer.outcome(), v1::UndoResponse::OUTCOME_CONFLICT);
  EXPECT_EQ(e.xs()[3], 7.0f);
  EXPECT_EQ(o.answer.conflicts(0).author(), "cleo");
  o = e.undo("ana", /*force=*/true);
  EXPECT_EQ(o.answer.outcome(), v1::UndoResponse::OUTCOME_DONE);
  EXPECT_EQ(e.xs()[3], 0.0f);
  // Cleo's value was overwritten: her own undo now conflicts with Ana's.
  EXPECT_EQ(e.undo("cleo").answer.outcome(), v1::UndoResponse::OUTCOME_CONFLICT);
}

TEST(EditHistory, AnUndoneChangeTheOthersBuiltOnIsNotRedoneOverThem) {
  Editing e;
  e.move("ana", {0}, 1.0f);
  e.undo("ana");
  e.move("ben", {0}, 9.0f);
  EXPECT_EQ(e.redo("ana").answer.outcome(), v1::UndoResponse::OUTCOME_CONFLICT);
  EXPECT_EQ(e.xs()[0], 9.0f);
}

TEST(EditHistory, AGestureIsOneEntryAndANewChangeEndsTheRedo) {
  Editing e;
  // Three poses of one drag (gesture 7), seconds apart: one entry.
  e.move("ana", {0}, 1.0f, 7);
  e.move("ana", {0, 1}, 2.0f, 7);
  e.move("ana", {1}, 3.0f, 7);
  EXPECT_EQ(e.history.size(), 1u);
  e.undo("ana");
  EXPECT_EQ(e.xs(), (std::vector<float>{0, 0, 0, 0, 0, 0}));
  // Without a gesture id, changes under the pause apart join; over it, not.
  Editing p;
  std::vector<float> after = p.pose;
  after[0] = 1.0f;
  p.history.record_pose({"ana", 0, 10.0, 1}, v1::HistoryEntry::KIND_POSE, std::vector<std::uint32_t>{0}, p.pose, after);
  p.pose = after;
  after[0] = 2.0f;
  p.history.record_pose({"ana", 0, 10.2, 2}, v1::HistoryEntry::KIND_POSE, std::vector<std::uint32_t>{0}, p.pose, after);
  p.pose = after;
  EXPECT_EQ(p.history.size(), 1u);
  after[0] = 3.0f;
  p.history.record_pose({"ana", 0, 11.0, 3}, v1::HistoryEntry::KIND_POSE, std::vector<std::uint32_t>{0}, p.pose, after);
  p.pose = after;
  EXPECT_EQ(p.history.size(), 2u);
  // After an undo, a new change means the undone one cannot be redone.
  p.undo("ana");
  EXPECT_EQ(p.xs()[0], 2.0f);
  p.move("ana", {1}, 4.0f);
  EXPECT_EQ(p.redo("ana").answer.outcome(), v1::UndoResponse::OUTCOME_NOTHING);
}

TEST(EditHistory, WithoutAGestureIdAnotherStreamStartsANewEntry) {
  Editing e;
  std::vector<float> values{1.0f, 0.0f, 0.0f};
  e.history.record_pose({"ana", 0, 10.0, 1, /*stream=*/7}, v1::HistoryEntry::KIND_POSE, std::vector<std::uint32_t>{0}, e.pose, values);
  e.pose[0] = 1.0f;
  values[0] = 2.0f;
  // 0.1 s later, the same client on another Drive stream: its own entry.
  e.history.record_pose({"ana", 0, 10.1, 2, /*stream=*/8}, v1::HistoryEntry::KIND_POSE, std::vector<std::uint32_t>{0}, e.pose, values);
  EXPECT_EQ(e.history.size(), 2u);
}

TEST(EditHistory, ItsByteCountFollowsOpenEntriesAndDroppedOnes) {
  // Three authors' open entries under a bound of two, on a base of 5,000: the
  // oldest (open) is dropped. An open entry holds 4 bytes of slots a base
  // vertex; uncounted, dropping one wrapped the count below zero.
  constexpr std::size_t kLarge = 5000;
  EditHistory h(kLarge, HistoryLimits{2, 1u << 30, 0.5});
  std::vector<float> pose(3 * kLarge, 0.0f), values{1.0f, 0.0f, 0.0f};
  for (const char* author : {"ana", "ben", "cleo"})
    h.record_pose({author, 0, 1.0, 1}, v1::HistoryEntry::KIND_POSE, std::vector<std::uint32_t>{0}, pose, values);
  EXPECT_EQ(h.size(), 2u);
  EXPECT_GE(h.bytes(), 2 * 4 * kLarge) << "the two open entries' slots";
  EXPECT_LT(h.bytes(), 1u << 20);
  // Closing an entry (its author's undo) gives its slots back.
  const std::size_t open = h.bytes();
  h.undo({"ben", 0, 2.0, 2}, false, pose, 0.0);
  EXPECT_LT(h.bytes(), open - 4 * kLarge + 4096);
}

TEST(EditHistory, AFullPoseCountsOnlyTheVerticesItMoves) {
  Editing e;
  e.move("ana", {2}, 1.0f);
  // Ben sends every vertex, moving only vertex 4: Ana's undo of vertex 2 is no conflict.
  std::vector<float> after = e.pose;
  after[3 * 4] = 6.0f;
  e.history.record_pose({"ben", 0, e.now, ++e.version}, v1::HistoryEntry::KIND_POSE, {}, e.pose, after);
  e.pose = after;
  EXPECT_EQ(e.undo("ana").answer.outcome(), v1::UndoResponse::OUTCOME_DONE);
  EXPECT_EQ(e.xs(), (std::vector<float>{0, 0, 0, 0, 6, 0}));
}

TEST(EditHistory, ThresholdAndHandlesUndoToWhatTheyWere) {
  Editing e;
  e.history.record_threshold({"ana", 0, 1.0, 1}, 0.0, 2e5);
  HandleSet before, after{{17, Vec3(1, 2, 3)}};
  e.history.record_handles({"ben", 0, 2.0, 2}, before, after);
  HistoryOutcome o = e.history.undo({"ana", 0, 3.0, 3}, false, e.pose, 2e5);
  ASSERT_TRUE(o.threshold);
  EXPECT_EQ(*o.threshold, 0.0);
  o = e.history.undo({"ben", 0, 4.0, 4}, false, e.pose, 0.0);
  ASSERT_TRUE(o.handles);
  EXPECT_TRUE(o.handles->empty());
  o = e.history.redo({"ben", 0, 5.0, 5}, false, e.pose, 0.0);
  ASSERT_TRUE(o.handles);
  EXPECT_EQ(o.handles->size(), 1u);
}

TEST(EditHistory, CheckpointsRestoreAsAnUndoableEntryAndDiff) {
  Editing e;
  e.move("ana", {0, 1}, 1.0f);
  const v1::Checkpoint before_review = e.history.create_checkpoint({"ana", 0, e.now, e.version}, "before review", e.pose, 0.0);
  e.move("ben", {1, 2}, 5.0f);
  v1::CheckpointDiff d = e.history.diff(before_review.id(), e.pose, 0.0);
  EXPECT_EQ(std::vector<std::uint32_t>(d.base_vertices().begin(), d.base_vertices().end()), (std::vector<std::uint32_t>{1, 2}));
  EXPECT_DOUBLE_EQ(d.max_distance(), 5.0);
  HistoryOutcome o = e.history.restore({"cleo", 0, e.now, ++e.version}, before_review.id(), e.pose, 0.0);
  EXPECT_EQ(o.answer.outcome(), v1::UndoResponse::OUTCOME_DONE);
  EXPECT_EQ(e.xs(), (std::vector<float>{1, 1, 0, 0, 0, 0}));
  EXPECT_EQ(e.history.diff(before_review.id(), e.pose, 0.0).base_vertices_size(), 0);
  e.undo("cleo");
  EXPECT_EQ(e.xs(), (std::vector<float>{1, 5, 5, 0, 0, 0}));
  EXPECT_THROW(e.history.restore({"cleo", 0, e.now, e.version}, 99, e.pose, 0.0), std::out_of_range);
  EXPECT_THROW(e.history.create_checkpoint({"cleo", 0, e.now, e.version}, "", e.pose, 0.0), std::invalid_argument);
}

TEST(EditHistory, StatesWorkBackFromTheCurrentPose) {
  Editing e;
  e.move("ana", {0}, 1.0f);
  e.move("ben", {1}, 2.0f);
  e.move("ana", {0}, 3.0f);
  const auto states = e.history.states(0, 0, e.pose);
  ASSERT_EQ(states.size(), 3u);
  EXPECT_EQ(states[0].second[0], 1.0f);
  EXPECT_EQ(states[0].second[3], 0.0f);
  EXPECT_EQ(states[1].second[3], 2.0f);
  EXPECT_EQ(states[2].second[0], 3.0f);
  EXPECT_EQ(e.history.states(2, 2, e.pose).size(), 1u);
}

TEST(EditHistory, BoundsDropTheOldestEntries) {
  EditHistory h(kBase, HistoryLimits{3, 1u << 20, 0.5});
  std::vector<float> pose(3 * kBase, 0.0f);
  for (int i = 1; i <= 5; ++i) {
    std::vector<float> after = pose;
    after[0] = static_cast<float>(i);
    h.record_pose({"ana", 0, 10.0 * i, static_cast<std::uint64_t>(i)}, v1::HistoryEntry::KIND_POSE,
                  std::vector<std::uint32_t>{0}, pose, after);
    pose = after;
  }
  EXPECT_EQ(h.size(), 3u);
  EXPECT_EQ(h.describe(0).first_seq(), 3u);
  // Undo events are entries too: each pushes the oldest out, so two undos
  // (of changes 5 and 4) leave change 3 dropped, and nothing more to undo.
  for (int i = 0; i < 2; ++i) EXPECT_EQ(h.undo({"ana", 0, 100.0 + i, 10}, false, pose, 0.0).answer.outcome(), v1::UndoResponse::OUTCOME_DONE);
  EXPECT_EQ(pose[0], 3.0f);
  EXPECT_EQ(h.undo({"ana", 0, 200.0, 11}, false, pose, 0.0).answer.outcome(), v1::UndoResponse::OUTCOME_NOTHING);
}

TEST(EditHistory, SurvivesItsPersistedForm) {
  Editing e;
  e.move("ana", {0, 1}, 1.0f);
  e.move("ben", {1}, 2.0f);
  e.undo("ben");
  e.history.create_checkpoint({"ana", 0, e.now, e.version}, "kept", e.pose, 0.0);
  EditHistory back = EditHistory::deserialize(e.history.serialize(), kBase, HistoryLimits{});
  // The same entries and checkpoints (bytes differ by the slots an open
  // entry holds, which a restored history has none of: its entries are closed).
  v1::History before = e.history.describe(0), after = back.describe(0);
  EXPECT_LE(after.bytes(), before.bytes());
  before.clear_bytes();
  after.clear_bytes();
  EXPECT_EQ(after.SerializeAsString(), before.SerializeAsString());
  // It goes on where it was: Ben's redo, then Ana's undo.
  EXPECT_EQ(back.redo({"ben", 0, e.now, 9}, false, e.pose, 0.0).answer.outcome(), v1::UndoResponse::OUTCOME_DONE);
  EXPECT_EQ(e.pose[3], 2.0f);
  EXPECT_EQ(back.undo({"ana", 0, e.now, 10}, false, e.pose, 0.0).answer.outcome(), v1::UndoResponse::OUTCOME_PARTIAL);
  EXPECT_THROW(EditHistory::deserialize("garbage", kBase, HistoryLimits{}), std::runtime_error);
  EXPECT_THROW(EditHistory::deserialize(e.history.serialize(), kBase + 1, HistoryLimits{}), std::runtime_error);
}

}  // namespace
}  // namespace filigree::server
