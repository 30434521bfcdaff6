#include "server/edit_history.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>

#include "filigree/internal/session_record.pb.h"

namespace filigree::server {
namespace {

using Kind = v1::HistoryEntry::Kind;

bool undoable(Kind k) {
  return k == v1::HistoryEntry::KIND_POSE || k == v1::HistoryEntry::KIND_HANDLES ||
         k == v1::HistoryEntry::KIND_THRESHOLD || k == v1::HistoryEntry::KIND_RESTORE;
}

bool same_value(const float* a, const float* b) { return a[0] == b[0] && a[1] == b[1] && a[2] == b[2]; }

std::string vertices_phrase(std::size_t n) { return std::to_string(n) + (n == 1 ? " base vertex" : " base vertices"); }

}  // namespace

double unix_seconds() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

std::size_t EditHistory::Entry::bytes() const {
  std::size_t b = sizeof(Entry) + info.author().size() + (vertices.capacity() + slot.capacity()) * sizeof(Index) +
                  (before.capacity() + after.capacity()) * sizeof(float) + prev_writer.capacity() * sizeof(std::uint64_t);
  if (handles_before) b += (handles_before->size() + handles_after->size()) * sizeof(HandleSet::value_type);
  return b;
}

EditHistory::EditHistory(std::size_t base_vertices, HistoryLimits limits)
    : base_vertices_(base_vertices), limits_(limits), writer_(base_vertices, 0) {}

EditHistory::Entry* EditHistory::find(std::uint64_t seq) {
  if (entries_.empty() || seq < entries_.front().info.seq() || seq > entries_.back().info.seq()) return nullptr;
  return &entries_[seq - entries_.front().info.seq()];
}
const EditHistory::Entry* EditHistory::find(std::uint64_t seq) const { return const_cast<EditHistory*>(this)->find(seq); }

EditHistory::Entry& EditHistory::append(const ChangeOrigin& origin, Kind kind) {
  Entry& e = entries_.emplace_back();
  e.info.set_seq(next_seq_++);
  e.info.set_kind(kind);
  e.info.set_author(origin.author);
  e.info.set_start_time(origin.time);
  e.info.set_end_time(origin.time);
  e.info.set_gesture_id(origin.gesture);
  e.info.set_version(origin.version);
  bytes_ += e.bytes();
  dirty_ = true;
  return e;
}

void EditHistory::close_open(const std::string& author) {
  const auto it = open_.find(author);
  if (it == open_.end()) return;
  if (Entry* e = find(it->second)) {
    const std::size_t old_bytes = e->bytes();
    e->open = false;
    e->slot = {};
    e->slot.shrink_to_fit();
    bytes_ -= old_bytes - e->bytes();  // the slots counted while open go
  }
  open_.erase(it);
}

EditHistory::Entry& EditHistory::entry_for(const ChangeOrigin& origin, Kind kind) {
  if (const auto it = open_.find(origin.author); it != open_.end())
    if (Entry* e = find(it->second); e && e->open && e->info.kind() == kind) {
      const bool same_gesture = origin.gesture != 0
                                    ? e->info.gesture_id() == origin.gesture
                                    : e->info.gesture_id() == 0 && e->stream == origin.stream &&
                                          origin.time - e->info.end_time() < limits_.pause_seconds;
      if (same_gesture) return *e;
    }
  close_open(origin.author);
  // A new change: what the author undid can no longer be redone.
  redo_.erase(origin.author);
  Entry& e = append(origin, kind);
  const std::size_t old_bytes = e.bytes();
  e.open = true;
  e.stream = origin.stream;
  e.slot.assign(base_vertices_, kNoSlot);
  account(e, old_bytes);  // an open entry's slots count, and go with it
  open_[origin.author] = e.info.seq();
  trim();  // may drop old entries, never this one (the newest)
  return entries_.back();
}

void EditHistory::account(Entry& e, std::size_t old_bytes) {
  bytes_ = bytes_ - old_bytes + e.bytes();
  dirty_ = true;
}

void EditHistory::trim() {
  // The newest entry always stays, however large.
  while (entries_.size() > 1 && (entries_.size() > limits_.entries || bytes_ > limits_.bytes)) {
    Entry& old = entries_.front();
    if (old.open) open_.erase(old.info.author());
    bytes_ -= old.bytes();
    entries_.pop_front();
  }
}

void EditHistory::record_pose(const ChangeOrigin& origin, Kind kind, std::span<const std::uint32_t> indices,
                              std::span<const float> before, std::span<const float> after) {
  if (limits_.entries == 0) return;  // history off
  const std::size_t count = indices.empty() ? base_vertices_ : indices.size();
  // A full pose repeats every vertex: only the ones that move count as
  // touched (else every later undo by anyone would conflict with it).
  bool moves = false;
  for (std::size_t i = 0; i < count && !moves; ++i) {
    const std::size_t v = indices.empty() ? i : indices[i];
    moves = !same_value(&before[3 * v], &after[3 * i]);
  }
  if (!moves) return;
  Entry& e = entry_for(origin, kind);
  const std::size_t old_bytes = e.bytes();
  for (std::size_t i = 0; i < count; ++i) {
    const Index v = static_cast<Index>(indices.empty() ? i : indices[i]);
    std::uint32_t& slot = e.slot[v];
    if (slot == kNoSlot) {
      if (same_value(&before[3 * v], &after[3 * i])) continue;
      slot = static_cast<std::uint32_t>(e.vertices.size());
      e.vertices.push_back(v);
      e.before.insert(e.before.end(), &before[3 * v], &before[3 * v] + 3);
      e.after.insert(e.after.end(), &after[3 * i], &after[3 * i] + 3);
      e.prev_writer.push_back(writer_[v]);
    } else {
      std::copy(&after[3 * i], &after[3 * i] + 3, &e.after[3 * slot]);
    }
    writer_[v] = e.info.seq();
  }
  e.info.set_end_time(origin.time);
  e.info.set_version(origin.version);
  account(e, old_bytes);
  trim();
}

void EditHistory::record_handles(const ChangeOrigin& origin, const HandleSet& before, const HandleSet& after) {
  if (limits_.entries == 0) return;
  Entry& e = entry_for(origin, v1::HistoryEntry::KIND_HANDLES);
  const std::size_t old_bytes = e.bytes();
  if (!e.handles_before) e.handles_before = before;
  e.handles_after = after;
  e.info.set_end_time(origin.time);
  e.info.set_version(origin.version);
  account(e, old_bytes);
  trim();
}

void EditHistory::record_threshold(const ChangeOrigin& origin, double before, double after) {
  if (limits_.entries == 0) return;
  Entry& e = entry_for(origin, v1::HistoryEntry::KIND_THRESHOLD);
  if (!e.threshold_before) {
    e.threshold_before = before;
    e.prev_threshold_writer = threshold_writer_;
  }
  e.threshold_after = after;
  threshold_writer_ = e.info.seq();
  e.info.set_end_time(origin.time);
  e.info.set_version(origin.version);
  dirty_ = true;
}

HistoryOutcome EditHistory::apply(const ChangeOrigin& by, Entry& target, bool redo, bool force, std::span<float> pose,
                                  double threshold) {
  HistoryOutcome out;
  v1::UndoResponse& answer = out.answer;
  answer.set_entry(target.info.seq());
  // Redo takes back what the undo restored: the vertices (and threshold) of
  // the newest undo of it.
  const Entry* undo = nullptr;
  if (redo)
    for (auto it = entries_.rbegin(); it != entries_.rend() && !undo; ++it)
      if (it->info.kind() == v1::HistoryEntry::KIND_UNDO && it->info.target() == target.info.seq()) undo = &*it;
  std::vector<std::size_t> slots;
  for (std::size_t i = 0; i < target.vertices.size(); ++i)
    if (!redo || (undo && std::find(undo->vertices.begin(), undo->vertices.end(), target.vertices[i]) != undo->vertices.end()))
      slots.push_back(i);
  // Which vertices are still as the target (or its undo) left them.
  std::vector<std::size_t> ours;
  std::map<std::uint64_t, std::vector<std::uint32_t>> conflicts;  // by writer
  for (std::size_t i : slots) {
    const Index v = target.vertices[i];
    const std::uint64_t expected = redo ? target.prev_writer[i] : target.info.seq();
    if (writer_[v] == expected || force)
      ours.push_back(i);
    else
      conflicts[writer_[v]].push_back(v);
  }
  bool threshold_ours = false;
  if (redo ? undo && undo->threshold_before : target.threshold_before.has_value()) {
    const std::uint64_t expected = redo ? target.prev_threshold_writer : target.info.seq();
    threshold_ours = threshold_writer_ == expected || force;
    if (!threshold_ours) conflicts[threshold_writer_];
  }
  for (const auto& [writer, vertices] : conflicts) {
    v1::Conflict& c = *answer.add_conflicts();
    const Entry* w = find(writer);
    c.set_author(w ? w->info.author() : std::string());
    c.set_entry(writer);
    c.mutable_base_vertices()->Add(vertices.begin(), vertices.end());
  }
  const char* verb = redo ? "redo" : "undo";
  if (ours.empty() && !threshold_ours && !target.handles_before && !conflicts.empty()) {
    answer.set_outcome(v1::UndoResponse::OUTCOME_CONFLICT);
    answer.set_message(std::string("nothing to ") + verb + " of entry " + std::to_string(target.info.seq()) +
                       ": others changed all of it since (" + std::to_string(answer.conflicts_size()) + " conflicting entries)");
    return out;
  }
  const std::uint64_t target_seq = target.info.seq();
  // (A deque keeps references to its other elements when it grows.)
  Entry& event = append(by, redo ? v1::HistoryEntry::KIND_REDO : v1::HistoryEntry::KIND_UNDO);
  const std::size_t old_bytes = event.bytes();
  event.info.set_target(target_seq);
  for (std::size_t i : ours) {
    const Index v = target.vertices[i];
    const float* value = redo ? &target.after[3 * i] : &target.before[3 * i];
    event.vertices.push_back(v);
    event.before.insert(event.before.end(), &pose[3 * v], &pose[3 * v] + 3);
    event.after.insert(event.after.end(), value, value + 3);
    event.prev_writer.push_back(writer_[v]);
    std::copy(value, value + 3, &pose[3 * v]);
    writer_[v] = redo ? target_seq : target.prev_writer[i];
    out.changed.push_back(v);
  }
  if (threshold_ours) {
    out.threshold = redo ? *target.threshold_after : *target.threshold_before;
    event.threshold_before = threshold;
    event.threshold_after = *out.threshold;
    event.prev_threshold_writer = threshold_writer_;
    threshold_writer_ = redo ? target_seq : target.prev_threshold_writer;
  }
  if (target.handles_before) out.handles = redo ? *target.handles_after : *target.handles_before;
  target.info.set_undone(!redo);
  if (!redo) redo_[by.author].push_back(target_seq);
  account(event, old_bytes);
  answer.set_recorded(event.info.seq());
  answer.set_outcome(conflicts.empty() ? v1::UndoResponse::OUTCOME_DONE : v1::UndoResponse::OUTCOME_PARTIAL);
  std::string message = std::string(redo ? "redid" : "undid") + " entry " + std::to_string(target_seq) + " (" +
                        vertices_phrase(ours.size()) + ")";
  if (!conflicts.empty())
    message += "; kept the later changes of " + std::to_string(conflicts.size()) + " other entries";
  answer.set_message(message);
  dirty_ = true;
  trim();
  return out;
}

HistoryOutcome EditHistory::undo(const ChangeOrigin& by, bool force, std::span<float> pose, double threshold) {
  close_open(by.author);
  for (auto it = entries_.rbegin(); it != entries_.rend(); ++it)
    if (it->info.author() == by.author && undoable(it->info.kind()) && !it->info.undone())
      return apply(by, *it, false, force, pose, threshold);
  HistoryOutcome out;
  out.answer.set_outcome(v1::UndoResponse::OUTCOME_NOTHING);
  out.answer.set_message("nothing of " + (by.author.empty() ? std::string("this client") : by.author) + " to undo");
  return out;
}

HistoryOutcome EditHistory::redo(const ChangeOrigin& by, bool force, std::span<float> pose, double threshold) {
  close_open(by.author);
  std::vector<std::uint64_t>& stack = redo_[by.author];
  while (!stack.empty() && !find(stack.back())) stack.pop_back();  // dropped from the history
  if (stack.empty()) {
    redo_.erase(by.author);
    HistoryOutcome out;
    out.answer.set_outcome(v1::UndoResponse::OUTCOME_NOTHING);
    out.answer.set_message("nothing of " + (by.author.empty() ? std::string("this client") : by.author) + " to redo");
    return out;
  }
  const std::uint64_t seq = stack.back();
  HistoryOutcome out = apply(by, *find(seq), true, force, pose, threshold);
  if (out.answer.outcome() != v1::UndoResponse::OUTCOME_CONFLICT) {
    std::vector<std::uint64_t>& after = redo_[by.author];
    if (!after.empty() && after.back() == seq) after.pop_back();
  }
  return out;
}

v1::Checkpoint EditHistory::create_checkpoint(const ChangeOrigin& by, const std::string& name, std::span<const float> pose,
                                              double threshold) {
  if (name.empty() || name.size() > 200) throw std::invalid_argument("a checkpoint's name has 1 to 200 characters");
  constexpr std::size_t kMostCheckpoints = 100;
  if (checkpoints_.size() == kMostCheckpoints) checkpoints_.erase(checkpoints_.begin());
  CheckpointState& c = checkpoints_.emplace_back();
  c.info.set_id(next_checkpoint_++);
  c.info.set_name(name);
  c.info.set_author(by.author);
  c.info.set_time(by.time);
  c.info.set_version(by.version);
  c.info.set_after_entry(next_seq_ - 1);
  c.pose.assign(pose.begin(), pose.end());
  c.threshold = threshold;
  dirty_ = true;
  return c.info;
}

HistoryOutcome EditHistory::restore(const ChangeOrigin& by, std::uint64_t id, std::span<float> pose, double threshold) {
  const auto c = std::find_if(checkpoints_.begin(), checkpoints_.end(), [&](const CheckpointState& s) { return s.info.id() == id; });
  if (c == checkpoints_.end()) throw std::out_of_range("no checkpoint " + std::to_string(id));
  HistoryOutcome out;
  bool differs = c->threshold != threshold;
  for (std::size_t v = 0; v < base_vertices_ && !differs; ++v) differs = !same_value(&pose[3 * v], &c->pose[3 * v]);
  if (!differs) {
    out.answer.set_outcome(v1::UndoResponse::OUTCOME_NOTHING);
    out.answer.set_message("the session is at checkpoint '" + c->info.name() + "' already");
    return out;
  }
  close_open(by.author);
  redo_.erase(by.author);
  Entry& e = append(by, v1::HistoryEntry::KIND_RESTORE);
  const std::size_t old_bytes = e.bytes();
  e.info.set_target(id);
  for (Index v = 0; v < base_vertices_; ++v) {
    if (same_value(&pose[3 * v], &c->pose[3 * v])) continue;
    e.vertices.push_back(v);
    e.before.insert(e.before.end(), &pose[3 * v], &pose[3 * v] + 3);
    e.after.insert(e.after.end(), &c->pose[3 * v], &c->pose[3 * v] + 3);
    e.prev_writer.push_back(writer_[v]);
    std::copy(&c->pose[3 * v], &c->pose[3 * v] + 3, &pose[3 * v]);
    writer_[v] = e.info.seq();
    out.changed.push_back(v);
  }
  if (c->threshold != threshold) {
    e.threshold_before = threshold;
    e.threshold_after = c->threshold;
    e.prev_threshold_writer = threshold_writer_;
    threshold_writer_ = e.info.seq();
    out.threshold = c->threshold;
  }
  account(e, old_bytes);
  out.answer.set_outcome(v1::UndoResponse::OUTCOME_DONE);
  out.answer.set_entry(e.info.seq());
  out.answer.set_recorded(e.info.seq());
  out.answer.set_message("restored checkpoint '" + c->info.name() + "' (" + vertices_phrase(out.changed.size()) + ")");
  trim();
  return out;
}

v1::CheckpointDiff EditHistory::diff(std::uint64_t id, std::span<const float> pose, double threshold) const {
  const auto c = std::find_if(checkpoints_.begin(), checkpoints_.end(), [&](const CheckpointState& s) { return s.info.id() == id; });
  if (c == checkpoints_.end()) throw std::out_of_range("no checkpoint " + std::to_string(id));
  v1::CheckpointDiff d;
  d.set_checkpoint(id);
  double sum = 0.0, most = 0.0;
  for (std::size_t v = 0; v < base_vertices_; ++v) {
    double squared = 0.0;
    for (int k = 0; k < 3; ++k) squared += std::pow(double{pose[3 * v + k]} - double{c->pose[3 * v + k]}, 2);
    if (squared > 0.0) d.add_base_vertices(static_cast<std::uint32_t>(v));
    sum += squared;
    most = std::max(most, squared);
  }
  d.set_max_distance(std::sqrt(most));
  d.set_rms_distance(base_vertices_ ? std::sqrt(sum / static_cast<double>(base_vertices_)) : 0.0);
  d.set_threshold_differs(c->threshold != threshold);
  return d;
}

v1::History EditHistory::describe(std::size_t newest) const {
  v1::History h;
  const std::size_t skip = newest == 0 || newest >= entries_.size() ? 0 : entries_.size() - newest;
  for (std::size_t i = skip; i < entries_.size(); ++i) {
    v1::HistoryEntry& e = *h.add_entries();
    e = entries_[i].info;
    e.mutable_base_vertices()->Add(entries_[i].vertices.begin(), entries_[i].vertices.end());
  }
  for (const CheckpointState& c : checkpoints_) *h.add_checkpoints() = c.info;
  h.set_first_seq(entries_.empty() ? next_seq_ : entries_.front().info.seq());
  h.set_bytes(bytes_);
  return h;
}

std::vector<std::pair<const v1::HistoryEntry*, std::vector<float>>> EditHistory::states(std::uint64_t from, std::uint64_t to,
                                                                                       std::span<const float> pose) const {
  std::vector<std::pair<const v1::HistoryEntry*, std::vector<float>>> out;
  std::vector<float> state(pose.begin(), pose.end());
  for (auto it = entries_.rbegin(); it != entries_.rend(); ++it) {
    const std::uint64_t seq = it->info.seq();
    if (seq < from) break;
    if (to == 0 || seq <= to) out.emplace_back(&it->info, state);
    for (std::size_t i = 0; i < it->vertices.size(); ++i)
      std::copy(&it->before[3 * i], &it->before[3 * i] + 3, &state[3 * it->vertices[i]]);
  }
  std::reverse(out.begin(), out.end());
  return out;
}

std::map<std::string, std::pair<std::vector<std::uint32_t>, double>> EditHistory::latest_by_author() const {
  std::map<std::string, std::pair<std::vector<std::uint32_t>, double>> out;
  for (auto it = entries_.rbegin(); it != entries_.rend(); ++it)
    if (!it->vertices.empty() && !out.contains(it->info.author()))
      out[it->info.author()] = {std::vector<std::uint32_t>(it->vertices.begin(), it->vertices.end()), it->info.end_time()};
  return out;
}

std::string EditHistory::serialize() const {
  internal::HistoryRecord r;
  r.set_base_vertices(static_cast<std::uint32_t>(base_vertices_));
  r.set_next_seq(next_seq_);
  r.set_next_checkpoint(next_checkpoint_);
  r.mutable_writer()->Add(writer_.begin(), writer_.end());
  r.set_threshold_writer(threshold_writer_);
  const auto handles_into = [](const HandleSet& set, google::protobuf::RepeatedPtrField<internal::SessionHandle>& out) {
    for (const auto& [v, target] : set) {
      internal::SessionHandle& h = *out.Add();
      h.set_vertex(v);
      h.set_x(static_cast<float>(target.x()));
      h.set_y(static_cast<float>(target.y()));
      h.set_z(static_cast<float>(target.z()));
    }
  };
  for (const Entry& e : entries_) {
    internal::HistoryEntryRecord& o = *r.add_entries();
    *o.mutable_info() = e.info;
    o.mutable_vertices()->Add(e.vertices.begin(), e.vertices.end());
    o.mutable_before()->Add(e.before.begin(), e.before.end());
    o.mutable_after()->Add(e.after.begin(), e.after.end());
    o.mutable_prev_writer()->Add(e.prev_writer.begin(), e.prev_writer.end());
    if (e.handles_before) {
      o.set_has_handles(true);
      handles_into(*e.handles_before, *o.mutable_handles_before());
      handles_into(*e.handles_after, *o.mutable_handles_after());
    }
    if (e.threshold_before) {
      o.set_has_threshold(true);
      o.set_threshold_before(*e.threshold_before);
      o.set_threshold_after(*e.threshold_after);
      o.set_prev_threshold_writer(e.prev_threshold_writer);
    }
  }
  for (const CheckpointState& c : checkpoints_) {
    internal::CheckpointRecord& o = *r.add_checkpoints();
    *o.mutable_info() = c.info;
    o.mutable_pose()->Add(c.pose.begin(), c.pose.end());
    o.set_threshold(c.threshold);
  }
  for (const auto& [author, stack] : redo_) {
    internal::RedoStack& o = *r.add_redo();
    o.set_author(author);
    o.mutable_entries()->Add(stack.begin(), stack.end());
  }
  return r.SerializeAsString();
}

EditHistory EditHistory::deserialize(const std::string& bytes, std::size_t base_vertices, HistoryLimits limits) {
  internal::HistoryRecord r;
  const auto bad = [](const std::string& why) { return std::runtime_error("a session's history: " + why); };
  if (!r.ParseFromString(bytes)) throw bad("unreadable");
  if (r.base_vertices() != base_vertices || static_cast<std::size_t>(r.writer_size()) != base_vertices)
    throw bad("it is of another base mesh");
  EditHistory h(base_vertices, limits);
  h.next_seq_ = r.next_seq();
  h.next_checkpoint_ = r.next_checkpoint();
  h.writer_.assign(r.writer().begin(), r.writer().end());
  h.threshold_writer_ = r.threshold_writer();
  const auto handles_from = [](const auto& in) {
    HandleSet set;
    for (const internal::SessionHandle& s : in) set.emplace_back(s.vertex(), Vec3(s.x(), s.y(), s.z()));
    return set;
  };
  std::uint64_t previous = 0;
  for (const internal::HistoryEntryRecord& o : r.entries()) {
    const std::size_t n = static_cast<std::size_t>(o.vertices_size());
    if (o.info().seq() <= previous || o.info().seq() >= h.next_seq_ || (previous != 0 && o.info().seq() != previous + 1) ||
        static_cast<std::size_t>(o.before_size()) != 3 * n || static_cast<std::size_t>(o.after_size()) != 3 * n ||
        static_cast<std::size_t>(o.prev_writer_size()) != n)
      throw bad("entry " + std::to_string(o.info().seq()) + " is malformed");
    for (std::uint32_t v : o.vertices())
      if (v >= base_vertices) throw bad("entry " + std::to_string(o.info().seq()) + " names base vertex " + std::to_string(v));
    previous = o.info().seq();
    Entry& e = h.entries_.emplace_back();
    e.info = o.info();
    e.vertices.assign(o.vertices().begin(), o.vertices().end());
    e.before.assign(o.before().begin(), o.before().end());
    e.after.assign(o.after().begin(), o.after().end());
    e.prev_writer.assign(o.prev_writer().begin(), o.prev_writer().end());
    if (o.has_handles()) {
      e.handles_before = handles_from(o.handles_before());
      e.handles_after = handles_from(o.handles_after());
    }
    if (o.has_threshold()) {
      e.threshold_before = o.threshold_before();
      e.threshold_after = o.threshold_after();
      e.prev_threshold_writer = o.prev_threshold_writer();
    }
    h.bytes_ += e.bytes();
  }
  for (const internal::CheckpointRecord& o : r.checkpoints()) {
    if (static_cast<std::size_t>(o.pose_size()) != 3 * base_vertices) throw bad("checkpoint " + std::to_string(o.info().id()) + " is malformed");
    CheckpointState& c = h.checkpoints_.emplace_back();
    c.info = o.info();
    c.pose.assign(o.pose().begin(), o.pose().end());
    c.threshold = o.threshold();
  }
  for (const internal::RedoStack& o : r.redo()) h.redo_[o.author()].assign(o.entries().begin(), o.entries().end());
  return h;
}

}  // namespace filigree::server
