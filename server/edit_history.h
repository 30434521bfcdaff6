#pragma once
// A session's edit history (proto HistoryEntry): every accepted change of the
// base pose, the handles or the threshold as an entry with its author, and
// per-author undo and redo that leave other authors' later work alone.
//
// The model: each base vertex remembers the entry whose value it holds now
// (its *writer*). A change records, per vertex it touches, the value before,
// the value after and the previous writer. Undoing entry E restores `before`
// on the vertices whose writer is still E (and gives them back their previous
// writer); a vertex someone else wrote since is a conflict: it keeps their
// value unless the undo is forced. Redo is the same the other way. A gesture
// (one gesture id, or changes less than a pause apart) extends one entry.
// Not thread-safe: the session calls it under its lock.

#include <cstddef>
#include <cstdint>
#include <deque>
#include <map>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "filigree/v1/filigree.pb.h"
#include "mesh/tri_mesh.h"

namespace filigree::server {

// Unix seconds now: history entries' times (shown to people, kept across restarts).
double unix_seconds();

struct HistoryLimits {
  std::size_t entries = 1000;        // the oldest go first beyond these; 0: no history
  std::size_t bytes = 64u << 20;
  double pause_seconds = 0.5;        // gesture id 0: a longer pause starts a new entry
};

// One author's handles as SetHandles left them: vertex and target.
using HandleSet = std::vector<std::pair<Index, Vec3>>;

// Who made a change, in which gesture, when (Unix seconds) and the session
// version that frames including it will exceed.
struct ChangeOrigin {
  std::string author;
  std::uint64_t gesture = 0;
  double time = 0.0;
  std::uint64_t version = 0;
  // The stream the change came on (a Drive stream's driver id; 0: a unary
  // call): without a gesture id, another stream starts a new entry.
  std::uint64_t stream = 0;
};

// What an undo, redo or restore did; `pose` was changed in place. The
// threshold and the author's handles to set, when they change.
struct HistoryOutcome {
  v1::UndoResponse answer;
  std::vector<Index> changed;  // base vertices changed in the pose
  std::optional<double> threshold;
  std::optional<HandleSet> handles;
};

class EditHistory {
 public:
  EditHistory(std::size_t base_vertices, HistoryLimits limits);

  // A pose change: `indices` (base order; empty: every vertex) go from
  // `before` (the whole pose, 3 per base vertex) to `after` (3 per index; the
  // whole pose when indices is empty). Call before the pose changes. `kind`
  // is KIND_POSE, or KIND_HANDLES for the pose a handle solve made.
  void record_pose(const ChangeOrigin& origin, v1::HistoryEntry::Kind kind, std::span<const std::uint32_t> indices,
                   std::span<const float> before, std::span<const float> after);
  // The author's handles went from `before` to `after`.
  void record_handles(const ChangeOrigin& origin, const HandleSet& before, const HandleSet& after);
  void record_threshold(const ChangeOrigin& origin, double before, double after);

  // Undoes (redoes) `author`'s latest change not undone (undone since its
  // last new change), restoring `pose` in place; `threshold` is the
  // session's now. A forced one overwrites the others' later values.
  HistoryOutcome undo(const ChangeOrigin& by, bool force, std::span<float> pose, double threshold);
  HistoryOutcome redo(const ChangeOrigin& by, bool force, std::span<float> pose, double threshold);

  // Names the current state (name: 1 to 200 characters, else
  // std::invalid_argument).
  v1::Checkpoint create_checkpoint(const ChangeOrigin& by, const std::string& name, std::span<const float> pose,
                                   double threshold);
  // Goes back to checkpoint `id` as a new entry of `by.author`
  // (std::out_of_range: no such checkpoint).
  HistoryOutcome restore(const ChangeOrigin& by, std::uint64_t id, std::span<float> pose, double threshold);
  v1::CheckpointDiff diff(std::uint64_t id, std::span<const float> pose, double threshold) const;

  // The history as GetHistory answers (the newest `newest` entries; 0: all).
  v1::History describe(std::size_t newest) const;
  // The base pose after each entry of [from, to] (0: the oldest kept / the
  // newest), oldest first, worked back from `pose` (the current one).
  // Concurrent gestures on the same vertices count in the order they began.
  std::vector<std::pair<const v1::HistoryEntry*, std::vector<float>>> states(std::uint64_t from, std::uint64_t to,
                                                                            std::span<const float> pose) const;
  // Each author's latest change (its base vertices, its end time).
  std::map<std::string, std::pair<std::vector<std::uint32_t>, double>> latest_by_author() const;

  // What persists (--data-dir, Redis) and back; deserialize throws
  // std::runtime_error for bytes that are no history of `base_vertices`.
  std::string serialize() const;
  static EditHistory deserialize(const std::string& bytes, std::size_t base_vertices, HistoryLimits limits);

  std::size_t bytes() const { return bytes_; }
  std::size_t size() const { return entries_.size(); }
  // Changes recorded since the last call (for persisting only when needed).
  bool take_dirty() { return std::exchange(dirty_, false); }
  void mark_dirty() { dirty_ = true; }
  bool dirty() const { return dirty_; }

 private:
  struct Entry {
    v1::HistoryEntry info;  // vertices listed only when described
    std::vector<Index> vertices;
    std::vector<float> before, after;         // 3 per vertex
    std::vector<std::uint64_t> prev_writer;   // per vertex
    std::optional<HandleSet> handles_before, handles_after;
    std::optional<double> threshold_before, threshold_after;
    std::uint64_t prev_threshold_writer = 0;
    // Per base vertex, its index in `vertices` (kNoSlot: none), while open:
    // a drag merges 60 poses a second into one entry, and a hash map's
    // lookups cost ~0.5 ms a full pose of 5,000 vertices.
    std::vector<std::uint32_t> slot;
    bool open = false;
    std::uint64_t stream = 0;  // ChangeOrigin::stream of its first change
    std::size_t bytes() const;
  };
  static constexpr std::uint32_t kNoSlot = ~std::uint32_t{0};
  struct CheckpointState {
    v1::Checkpoint info;
    std::vector<float> pose;
    double threshold = 0.0;
  };

  Entry* find(std::uint64_t seq);
  const Entry* find(std::uint64_t seq) const;
  // The author's open entry of `kind` if `origin` continues its gesture;
  // else closes it and opens a new one.
  Entry& entry_for(const ChangeOrigin& origin, v1::HistoryEntry::Kind kind);
  void close_open(const std::string& author);
  Entry& append(const ChangeOrigin& origin, v1::HistoryEntry::Kind kind);
  // Sets vertex v to `value` in `pose` inside entry e (before: the pose's now).
  void write_vertex(Entry& e, Index v, std::span<float> pose, const float* value, std::uint64_t writer);
  void account(Entry& e, std::size_t old_bytes);
  void trim();
  HistoryOutcome apply(const ChangeOrigin& by, Entry& target, bool redo, bool force, std::span<float> pose,
                       double threshold);

  std::size_t base_vertices_;
  HistoryLimits limits_;
  std::deque<Entry> entries_;
  std::uint64_t next_seq_ = 1;
  std::vector<std::uint64_t> writer_;  // per base vertex
  std::uint64_t threshold_writer_ = 0;
  std::map<std::string, std::uint64_t> open_;            // author → open entry
  std::map<std::string, std::vector<std::uint64_t>> redo_;  // author → undone entries, newest last
  std::vector<CheckpointState> checkpoints_;
  std::uint64_t next_checkpoint_ = 1;
  std::size_t bytes_ = 0;
  bool dirty_ = false;
};

}  // namespace filigree::server
