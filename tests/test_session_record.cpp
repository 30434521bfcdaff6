// The session record (server/session_record.h) as stored: handles and the
// adaptive cut round-trip through records and journaled progress, and records
// and progress written before they were kept still read (as none).

#include <gtest/gtest.h>

#include "filigree/internal/session_record.pb.h"
#include "server/session_record.h"

namespace filigree::server {
namespace {

SessionRecord sample() {
  SessionRecord r;
  r.id = "0123456789abcdef0123";
  r.hierarchy_key = "abc";
  r.options.set_threshold(2e4);
  r.editor_token.assign(32, 'e');  // (a one-letter literal trips GCC 12's -Wrestrict)
  r.viewer_token.assign(32, 'v');
  r.pose = {1.0f, 2.0f, 3.0f};
  r.version = 7;
  // Two clients, one vertex held by both (the later wins there).
  r.handles = {{100, "alice", {0.5f, -1.25f, 3.0f}}, {1500, "bob", {1e-7f, 2.0f, -0.0f}}, {100, "bob", {9.0f, 8.0f, 7.0f}}};
  r.handles_pending = true;
  r.cut.unrecovered = {3, 17, 40};
  r.cut.scores = {0.0f, 0.25f, 1.5f, 3e-6f, 0.0f};
  r.cut.next_block = 2;
  return r;
}

void expect_same_progress(const SessionRecord& got, const SessionRecord& want) {
  EXPECT_EQ(got.pose, want.pose);
  EXPECT_EQ(got.version, want.version);
  EXPECT_EQ(got.options.threshold(), want.options.threshold());
  EXPECT_EQ(got.handles, want.handles);
  EXPECT_EQ(got.handles_pending, want.handles_pending);
  EXPECT_EQ(got.cut.unrecovered, want.cut.unrecovered);
  EXPECT_EQ(got.cut.scores, want.cut.scores);
  EXPECT_EQ(got.cut.next_block, want.cut.next_block);
}

TEST(SessionRecordTest, HandlesAndTheCutRoundTrip) {
  const SessionRecord r = sample();
  const SessionRecord back = decode_session_record(encode_session_record(r));
  EXPECT_EQ(back.id, r.id);
  expect_same_progress(back, r);
}

TEST(SessionRecordTest, ProgressCarriesHandlesAndAppliesOntoARecord) {
  const SessionRecord r = sample();
  SessionRecord target;
  target.id = r.id;
  apply_session_progress(encode_session_progress(progress_of(r)), target);
  expect_same_progress(target, r);

  // A journaled change has no cut: the record keeps the one it had, and
  // takes the change's handles (here: none left).
  SessionProgress change = progress_of(r);
  change.cut = {};
  change.handles.clear();
  change.handles_pending = false;
  change.version = 9;
  change.pose = {4, 5, 6};
  apply_session_progress(encode_session_progress(change), target);
  EXPECT_EQ(target.pose, change.pose);
  EXPECT_TRUE(target.handles.empty());
  EXPECT_FALSE(target.handles_pending);
  EXPECT_EQ(target.version, 9u);
  EXPECT_EQ(target.cut.unrecovered, r.cut.unrecovered);
  EXPECT_EQ(target.cut.scores, r.cut.scores);
  EXPECT_EQ(target.cut.next_block, r.cut.next_block);
  // The file store's path (progress applied directly) agrees.
  SessionRecord direct = r;
  apply_progress(change, direct);
  expect_same_progress(direct, target);
}

TEST(SessionRecordTest, RecordsWithoutHandlesOrCutStillRead) {
  // Written as processes before this change wrote them: fields 1–11 only.
  internal::SessionRecord old;
  old.set_format_version(1);
  old.set_session_id("0123456789abcdef0123");
  old.set_hierarchy_key("abc");
  old.add_pose(1.0f);
  old.set_version(3);
  const SessionRecord r = decode_session_record(old.SerializeAsString());
  EXPECT_EQ(r.version, 3u);
  EXPECT_TRUE(r.handles.empty());
  EXPECT_FALSE(r.handles_pending);
  EXPECT_TRUE(r.cut.empty());

  // Old progress (options, pose, version) onto a record with handles: the
  // writer had none, so none remain.
  SessionRecord with = sample();
  internal::SessionRecord progress;
  progress.set_format_version(1);
  progress.add_pose(4.0f);
  progress.set_version(11);
  apply_session_progress(progress.SerializeAsString(), with);
  EXPECT_TRUE(with.handles.empty());
  EXPECT_EQ(with.version, 11u);
}

TEST(SessionRecordTest, AnEmptyCutIsNotWritten) {
  SessionRecord r = sample();
  r.cut = {};
  internal::SessionRecord p;
  ASSERT_TRUE(p.ParseFromString(encode_session_record(r).substr(12)));  // after "FGSR" and the checksum
  EXPECT_FALSE(p.has_cut());
  EXPECT_TRUE(decode_session_record(encode_session_record(r)).cut.empty());
}

// A stored version past 2^62 is refused: the next frame would have wrapped
// to version 0 and reused versions clients have seen.
TEST(SessionRecordTest, VersionsPastTheLargestAreRefused) {
  SessionRecord r = sample();
  r.version = kMaxSessionVersion;
  EXPECT_EQ(decode_session_record(encode_session_record(r)).version, kMaxSessionVersion);
  r.version = kMaxSessionVersion + 1;
  EXPECT_THROW(decode_session_record(encode_session_record(r)), std::runtime_error);
  SessionProgress p = progress_of(sample());
  p.version = ~std::uint64_t{0};
  EXPECT_THROW(decode_session_progress(encode_session_progress(p)), std::runtime_error);
}

// Stored bytes carry a checksum: any flipped byte of a record or a progress
// is refused as corrupt, not read as another pose, version or token.
TEST(SessionRecordTest, EveryFlippedByteIsCaught) {
  const std::string record = encode_session_record(sample());
  ASSERT_EQ(record.substr(0, 4), "FGSR");
  EXPECT_EQ(decode_session_record(record).editor_token, sample().editor_token);
  for (std::size_t at = 0; at < record.size(); ++at) {
    std::string flipped = record;
    flipped[at] = static_cast<char>(flipped[at] ^ 0x10);
    EXPECT_THROW(decode_session_record(flipped), std::runtime_error) << "byte " << at;
  }
  const std::string progress = encode_session_progress(progress_of(sample()));
  for (std::size_t at = 4; at < progress.size(); ++at) {
    std::string flipped = progress;
    flipped[at] = static_cast<char>(flipped[at] ^ 0x01);
    EXPECT_THROW(decode_session_progress(flipped), std::runtime_error) << "byte " << at;
  }
  EXPECT_THROW(decode_session_record(record.substr(0, 10)), std::runtime_error);
}

}  // namespace
}  // namespace filigree::server
