#pragma once
// What an undo, a redo or a checkpoint's restore did (v1::UndoResponse):
// every vertex restored, some kept by others' later work, nothing.

#include <cstdint>
#include <string>
#include <vector>

#include "filigree/v1/filigree.pb.h"

namespace filigree {

// Another author's later change on base vertices the undo, redo or restore
// would have changed: those vertices keep that work.
struct EditConflict {
  std::string author;
  std::uint64_t entry = 0;                  // their history entry
  std::vector<std::uint32_t> base_vertices;  // base order
};

struct EditOutcome {
  enum class Result {
    kDone,      // every vertex restored
    kPartial,   // restored but the conflicts' vertices
    kConflict,  // every vertex conflicts: nothing changed
    kNothing,   // nothing to undo or redo
  };
  Result result = Result::kNothing;
  std::uint64_t entry = 0;     // the change undone or redone (a restore: the new entry)
  std::uint64_t recorded = 0;  // the history entry this made; 0 if nothing changed
  std::vector<EditConflict> conflicts;
  // Every frame with a larger version includes the result.
  std::uint64_t accepted_at_version = 0;
  std::string message;  // what happened, in a sentence

  bool changed() const { return recorded != 0; }
};

// Copies `response` (an unknown outcome, from a newer server, reads as kNothing).
EditOutcome to_edit_outcome(const v1::UndoResponse& response);

// "done", "partial", "conflict", "nothing".
const char* result_name(EditOutcome::Result result);

}  // namespace filigree
