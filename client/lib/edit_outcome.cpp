#include "filigree/edit_outcome.h"

namespace filigree {

EditOutcome to_edit_outcome(const v1::UndoResponse& response) {
  EditOutcome out;
  switch (response.outcome()) {
    case v1::UndoResponse::OUTCOME_DONE: out.result = EditOutcome::Result::kDone; break;
    case v1::UndoResponse::OUTCOME_PARTIAL: out.result = EditOutcome::Result::kPartial; break;
    case v1::UndoResponse::OUTCOME_CONFLICT: out.result = EditOutcome::Result::kConflict; break;
    default: out.result = EditOutcome::Result::kNothing; break;
  }
  out.entry = response.entry();
  out.recorded = response.recorded();
  out.accepted_at_version = response.accepted_at_version();
  out.message = response.message();
  out.conflicts.reserve(static_cast<std::size_t>(response.conflicts_size()));
  for (const v1::Conflict& c : response.conflicts())
    out.conflicts.push_back({c.author(), c.entry(), {c.base_vertices().begin(), c.base_vertices().end()}});
  return out;
}

const char* result_name(EditOutcome::Result result) {
  switch (result) {
    case EditOutcome::Result::kDone: return "done";
    case EditOutcome::Result::kPartial: return "partial";
    case EditOutcome::Result::kConflict: return "conflict";
    case EditOutcome::Result::kNothing: return "nothing";
  }
  return "nothing";
}

}  // namespace filigree
