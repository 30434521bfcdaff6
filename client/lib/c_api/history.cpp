// The history, undo and redo, and checkpoints.

#include <algorithm>

#include "c_api/collaboration.h"

namespace filigree::c_api {
namespace {

constexpr const char* kDefaultName = "filigree-c";

// Copies `outcome` out and keeps its message and conflicts in the session handle.
int report_edit(filigree_session& s, const EditOutcome& outcome, filigree_edit_outcome* out) {
  std::string conflicts;
  std::uint64_t vertices = 0;
  for (const EditConflict& c : outcome.conflicts) {
    std::string author = c.author;
    std::replace_if(author.begin(), author.end(), [](char ch) { return ch == '\t' || ch == '\n' || ch == '\r'; }, ' ');
    conflicts += author;
    conflicts += '\t';
    conflicts += std::to_string(c.entry);
    conflicts += '\t';
    for (std::size_t i = 0; i < c.base_vertices.size(); ++i) {
      if (i > 0) conflicts += ' ';
      conflicts += std::to_string(c.base_vertices[i]);
    }
    conflicts += '\n';
    vertices += c.base_vertices.size();
  }
  {
    std::lock_guard lock(s.edit_mutex);
    s.edit_message = outcome.message;
    s.edit_conflicts = std::move(conflicts);
  }
  if (out) {
    *out = filigree_edit_outcome{};
    out->result = static_cast<std::int32_t>(outcome.result);  // the enums agree (edit_outcome.h, filigree.h)
    out->conflict_count = static_cast<std::uint32_t>(outcome.conflicts.size());
    out->entry = outcome.entry;
    out->recorded = outcome.recorded;
    out->accepted_at_version = outcome.accepted_at_version;
    out->conflict_vertex_count = vertices;
  }
  return FILIGREE_OK;
}

static_assert(static_cast<int>(EditOutcome::Result::kDone) == FILIGREE_EDIT_DONE &&
              static_cast<int>(EditOutcome::Result::kPartial) == FILIGREE_EDIT_PARTIAL &&
              static_cast<int>(EditOutcome::Result::kConflict) == FILIGREE_EDIT_CONFLICT &&
              static_cast<int>(EditOutcome::Result::kNothing) == FILIGREE_EDIT_NOTHING);

filigree_checkpoint to_c(const v1::Checkpoint& c) {
  return filigree_checkpoint{c.id(), c.time(), c.version(), c.after_entry()};
}

// An index into the entries or checkpoints of a history handle, checked.
int out_of_range(const filigree_history& h, const char* function, const char* what, std::size_t index, int count) {
  return fail(&h.error, FILIGREE_OUT_OF_RANGE,
              std::string(function) + ": " + what + " " + std::to_string(index) + " of " + std::to_string(count));
}

template <class Body>
int with_entry(const filigree_history* history, const char* function, std::size_t index, Body&& body) {
  return with_handle(history, function, [&](const filigree_history& h) -> int {
    if (index >= static_cast<std::size_t>(h.history.entries_size()))
      return out_of_range(h, function, "entry", index, h.history.entries_size());
    return body(h, h.history.entries(static_cast<int>(index)));
  });
}

template <class Body>
int with_checkpoint(const filigree_history* history, const char* function, std::size_t index, Body&& body) {
  return with_handle(history, function, [&](const filigree_history& h) -> int {
    if (index >= static_cast<std::size_t>(h.history.checkpoints_size()))
      return out_of_range(h, function, "checkpoint", index, h.history.checkpoints_size());
    return body(h, h.history.checkpoints(static_cast<int>(index)));
  });
}

}  // namespace
}  // namespace filigree::c_api

using namespace filigree::c_api;

extern "C" {

int filigree_undo(filigree_session* session, const char* token, const char* client_name, int force,
                  filigree_edit_outcome* outcome) {
  return with_handle(session, "filigree_undo", [&](filigree_session& s) -> int {
    return report_edit(s,
                       s.connection->client.undo(s.mesh.session_id, token ? token : s.token,
                                                 client_name ? client_name : kDefaultName, force != 0),
                       outcome);
  });
}

int filigree_redo(filigree_session* session, const char* token, const char* client_name, int force,
                  filigree_edit_outcome* outcome) {
  return with_handle(session, "filigree_redo", [&](filigree_session& s) -> int {
    return report_edit(s,
                       s.connection->client.redo(s.mesh.session_id, token ? token : s.token,
                                                 client_name ? client_name : kDefaultName, force != 0),
                       outcome);
  });
}

int filigree_session_edit_message(const filigree_session* session, char* buffer, size_t capacity, size_t* required) {
  constexpr const char* kFunction = "filigree_session_edit_message";
  return with_handle(session, kFunction, [&](const filigree_session& s) -> int {
    std::lock_guard lock(s.edit_mutex);
    return copy_string(&s.error, kFunction, s.edit_message, buffer, capacity, required);
  });
}

int filigree_session_edit_conflicts(const filigree_session* session, char* buffer, size_t capacity,
                                    size_t* required) {
  constexpr const char* kFunction = "filigree_session_edit_conflicts";
  return with_handle(session, kFunction, [&](const filigree_session& s) -> int {
    std::lock_guard lock(s.edit_mutex);
    return copy_string(&s.error, kFunction, s.edit_conflicts, buffer, capacity, required);
  });
}

int filigree_create_checkpoint(filigree_session* session, const char* token, const char* name,
                               const char* client_name, filigree_checkpoint* checkpoint) {
  constexpr const char* kFunction = "filigree_create_checkpoint";
  return with_handle(session, kFunction, [&](filigree_session& s) -> int {
    if (!name) return null_argument(&s.error, kFunction, "name");
    const filigree::v1::Checkpoint made = s.connection->client.create_checkpoint(
        s.mesh.session_id, token ? token : s.token, name, client_name ? client_name : kDefaultName);
    if (checkpoint) *checkpoint = to_c(made);
    return FILIGREE_OK;
  });
}

int filigree_restore_checkpoint(filigree_session* session, const char* token, uint64_t id, const char* client_name,
                                filigree_edit_outcome* outcome) {
  return with_handle(session, "filigree_restore_checkpoint", [&](filigree_session& s) -> int {
    return report_edit(s,
                       s.connection->client.restore_checkpoint(s.mesh.session_id, token ? token : s.token, id,
                                                               client_name ? client_name : kDefaultName),
                       outcome);
  });
}

int filigree_diff_checkpoint(filigree_session* session, const char* token, uint64_t id, filigree_checkpoint_diff* diff,
                             uint32_t* vertices, size_t capacity, size_t* required) {
  constexpr const char* kFunction = "filigree_diff_checkpoint";
  return with_handle(session, kFunction, [&](filigree_session& s) -> int {
    if (!diff) return null_argument(&s.error, kFunction, "diff");
    const filigree::v1::CheckpointDiff d =
        s.connection->client.diff_checkpoint(s.mesh.session_id, token ? token : s.token, id);
    *diff = filigree_checkpoint_diff{d.checkpoint(),    d.version(),      static_cast<uint64_t>(d.base_vertices_size()),
                                     d.max_distance(), d.rms_distance(), d.threshold_differs() ? 1 : 0};
    if (!vertices && capacity == 0) {  // diff alone
      if (required) *required = static_cast<std::size_t>(d.base_vertices_size());
      return FILIGREE_OK;
    }
    return copy_out(&s.error, kFunction, d.base_vertices().data(), static_cast<std::size_t>(d.base_vertices_size()),
                    sizeof(std::uint32_t), vertices, capacity, required);
  });
}

int filigree_history_read(filigree_session* session, const char* token, uint32_t newest, filigree_history** out) {
  constexpr const char* kFunction = "filigree_history_read";
  return with_handle(session, kFunction, [&](filigree_session& s) -> int {
    if (!out) return null_argument(&s.error, kFunction, "out");
    *out = nullptr;
    auto handle = std::make_unique<filigree_history>();
    handle->history = s.connection->client.history(s.mesh.session_id, token ? token : s.token, newest);
    return hand_out(std::move(handle), out);
  });
}

int filigree_history_info_get(const filigree_history* history, filigree_history_info* info) {
  constexpr const char* kFunction = "filigree_history_info_get";
  return with_handle(history, kFunction, [&](const filigree_history& h) -> int {
    if (!info) return null_argument(&h.error, kFunction, "info");
    *info = filigree_history_info{static_cast<uint64_t>(h.history.entries_size()),
                                  static_cast<uint64_t>(h.history.checkpoints_size()), h.history.first_seq(),
                                  h.history.bytes()};
    return FILIGREE_OK;
  });
}

int filigree_history_entry_get(const filigree_history* history, size_t index, filigree_history_entry* entry) {
  constexpr const char* kFunction = "filigree_history_entry_get";
  return with_entry(history, kFunction, index, [&](const filigree_history& h, const filigree::v1::HistoryEntry& e) -> int {
    if (!entry) return null_argument(&h.error, kFunction, "entry");
    *entry = filigree_history_entry{};
    entry->seq = e.seq();
    entry->kind = static_cast<int32_t>(e.kind());  // the contract's numbers (filigree_history_kind)
    entry->undone = e.undone() ? 1 : 0;
    entry->start_time = e.start_time();
    entry->end_time = e.end_time();
    entry->target = e.target();
    entry->gesture_id = e.gesture_id();
    entry->version = e.version();
    entry->vertex_count = static_cast<uint64_t>(e.base_vertices_size());
    return FILIGREE_OK;
  });
}

int filigree_history_entry_author(const filigree_history* history, size_t index, char* buffer, size_t capacity,
                                  size_t* required) {
  constexpr const char* kFunction = "filigree_history_entry_author";
  return with_entry(history, kFunction, index, [&](const filigree_history& h, const filigree::v1::HistoryEntry& e) {
    return copy_string(&h.error, kFunction, e.author(), buffer, capacity, required);
  });
}

int filigree_history_entry_vertices(const filigree_history* history, size_t index, uint32_t* buffer, size_t capacity,
                                    size_t* required) {
  constexpr const char* kFunction = "filigree_history_entry_vertices";
  return with_entry(history, kFunction, index, [&](const filigree_history& h, const filigree::v1::HistoryEntry& e) {
    return copy_out(&h.error, kFunction, e.base_vertices().data(), static_cast<std::size_t>(e.base_vertices_size()),
                    sizeof(std::uint32_t), buffer, capacity, required);
  });
}

int filigree_history_checkpoint_get(const filigree_history* history, size_t index, filigree_checkpoint* checkpoint) {
  constexpr const char* kFunction = "filigree_history_checkpoint_get";
  return with_checkpoint(history, kFunction, index, [&](const filigree_history& h, const filigree::v1::Checkpoint& c) {
    if (!checkpoint) return null_argument(&h.error, kFunction, "checkpoint");
    *checkpoint = to_c(c);
    return static_cast<int>(FILIGREE_OK);
  });
}

int filigree_history_checkpoint_name(const filigree_history* history, size_t index, char* buffer, size_t capacity,
                                     size_t* required) {
  constexpr const char* kFunction = "filigree_history_checkpoint_name";
  return with_checkpoint(history, kFunction, index, [&](const filigree_history& h, const filigree::v1::Checkpoint& c) {
    return copy_string(&h.error, kFunction, c.name(), buffer, capacity, required);
  });
}

int filigree_history_checkpoint_author(const filigree_history* history, size_t index, char* buffer, size_t capacity,
                                       size_t* required) {
  constexpr const char* kFunction = "filigree_history_checkpoint_author";
  return with_checkpoint(history, kFunction, index, [&](const filigree_history& h, const filigree::v1::Checkpoint& c) {
    return copy_string(&h.error, kFunction, c.author(), buffer, capacity, required);
  });
}

const char* filigree_history_last_error(const filigree_history* history) {
  return is_handle(history, filigree_history::kKind) ? history->error.get() : invalid_handle_message();
}

int filigree_history_free(filigree_history* history) {
  if (!history) return FILIGREE_OK;
  if (!unregister_handle(history, filigree_history::kKind))
    return fail(nullptr, FILIGREE_ERROR_INVALID_HANDLE,
                "filigree_history_free: not a live filigree_history (freed, or another kind of handle)");
  delete history;
  return FILIGREE_OK;
}

}  // extern "C"
