#include "server/session.h"
// Session's edit history side (edit_history.h): reading it, undo and redo,
// checkpoints, and keeping it with the session's record.

#include <cmath>
#include <limits>

#include <spdlog/spdlog.h>

#include "runtime/deformer.h"

namespace filigree::server {
v1::History Session::history(std::size_t newest) const {
  std::lock_guard lock(mutex_);
  return history_.describe(newest);
}

double Session::threshold_locked() const {
  return record_.options.whole_mesh() ? DeformerOptions::kInfinity : record_.options.threshold();
}

std::uint64_t Session::apply_history_locked(const std::string& author, const HistoryOutcome& outcome,
                                            SessionProgress& progress) {
  if (outcome.handles) {
    // The author's handles as they were; the pose is restored already, so
    // nothing is solved again.
    for (auto it = handles_.begin(); it != handles_.end();) {
      std::erase_if(it->second, [&](const HandleEntry& e) { return e.client == author; });
      it = it->second.empty() ? handles_.erase(it) : std::next(it);
    }
    for (const auto& [v, target] : *outcome.handles) handles_[v].push_back({target, author, ++handle_stamp_});
  }
  if (!outcome.changed.empty() || outcome.handles) {
    v1::Change& change = changes_[author];
    change.set_client_name(author);
    change.set_vertex_count(change.vertex_count() + static_cast<std::uint32_t>(outcome.changed.size()));
    pending_ = true;
    maybe_compute_locked();
  }
  publish_presence_locked(/*paced=*/false);
  const std::uint64_t seq = ++journal_seq_;
  if (journal_) progress = progress_with_change_locked();
  touch();
  return seq;
}

v1::UndoResponse Session::finish_history(HistoryOutcome outcome, std::uint64_t seq, SessionProgress& progress,
                                         std::uint64_t accepted) {
  journal(progress, seq);
  if (outcome.threshold) {
    const bool whole = std::isinf(*outcome.threshold);
    accepted = std::max(accepted, set_threshold(whole ? 0.0 : *outcome.threshold, whole, nullptr));
  }
  persist_history();
  outcome.answer.set_accepted_at_version(accepted);
  return std::move(outcome.answer);
}

v1::UndoResponse Session::change_by_history(const std::string& author,
                                            const std::function<HistoryOutcome(const ChangeOrigin&)>& act) {
  HistoryOutcome outcome;
  std::uint64_t seq = 0, accepted = 0;
  SessionProgress progress;
  {
    std::lock_guard lock(mutex_);
    if (evicted_) throw_evicted();
    accepted = assigned_version_;
    outcome = act({author, 0, unix_seconds(), assigned_version_});
    const v1::UndoResponse::Outcome o = outcome.answer.outcome();
    if (o == v1::UndoResponse::OUTCOME_NOTHING || o == v1::UndoResponse::OUTCOME_CONFLICT) {  // nothing changed
      outcome.answer.set_accepted_at_version(accepted);
      return std::move(outcome.answer);
    }
    seq = apply_history_locked(author, outcome, progress);
  }
  return finish_history(std::move(outcome), seq, progress, accepted);
}

v1::UndoResponse Session::undo(const std::string& author, bool redo, bool force) {
  return change_by_history(author, [&](const ChangeOrigin& by) {
    return redo ? history_.redo(by, force, record_.pose, threshold_locked())
                : history_.undo(by, force, record_.pose, threshold_locked());
  });
}

v1::Checkpoint Session::create_checkpoint(const std::string& author, const std::string& name) {
  v1::Checkpoint made;
  {
    std::lock_guard lock(mutex_);
    if (evicted_) throw_evicted();
    made = history_.create_checkpoint({author, 0, unix_seconds(), assigned_version_}, name, record_.pose, threshold_locked());
  }
  persist_history();
  return made;
}

v1::UndoResponse Session::restore_checkpoint(const std::string& author, std::uint64_t id) {
  return change_by_history(author, [&](const ChangeOrigin& by) {
    return history_.restore(by, id, record_.pose, threshold_locked());
  });
}

v1::CheckpointDiff Session::diff_checkpoint(std::uint64_t id) const {
  std::lock_guard lock(mutex_);
  v1::CheckpointDiff d = history_.diff(id, record_.pose, threshold_locked());
  d.set_version(record_.version);
  return d;
}

std::vector<std::pair<v1::HistoryEntry, std::vector<float>>> Session::history_states(std::uint64_t from,
                                                                                     std::uint64_t to) const {
  std::lock_guard lock(mutex_);
  std::vector<std::pair<v1::HistoryEntry, std::vector<float>>> out;
  for (auto& [entry, pose] : history_.states(from, to, record_.pose)) out.emplace_back(*entry, std::move(pose));
  return out;
}

std::map<std::string, std::pair<std::vector<std::uint32_t>, double>> Session::latest_changes() const {
  std::lock_guard lock(mutex_);
  return history_.latest_by_author();
}

void Session::persist_history(bool tick) {
  if (!journal_.write_history) return;
  std::string bytes;
  {
    std::lock_guard lock(mutex_);
    const auto now = std::chrono::steady_clock::now();
    // The history is written whole, serialized under this lock (tens of ms
    // at its bound): while a drag goes on the tick waits for a second's pause
    // (at most 10 s), so the drag's frames are not held for it.
    if (!history_.dirty()) {
      history_saved_ = now;  // the 10 s count from when it last had nothing to write
      return;
    }
    if (tick && now - last_activity_ < std::chrono::seconds(1) && now - history_saved_ < std::chrono::seconds(10)) return;
    history_.take_dirty();
    history_saved_ = now;
    bytes = history_.serialize();
  }
  try {
    journal_.write_history(bytes);
  } catch (const std::exception& e) {
    std::lock_guard lock(mutex_);
    history_.mark_dirty();  // tried again at the next tick
    spdlog::warn("session={} event=history_not_saved error=\"{}\"", record_.id, e.what());
  }
}

}  // namespace filigree::server
