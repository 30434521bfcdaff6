#pragma once
// One state of a session's history as Client::export_history() gives it:
// the base pose after a history entry and the detailed mesh it deforms to.

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace filigree {

struct HistoryState {
  std::uint64_t entry = 0;    // the state after this history entry (HistoryEntry.seq)
  std::string author;         // the entry's
  double time = 0.0;          // its last change, Unix seconds
  std::uint64_t version = 0;  // the session's version at that change
  std::vector<float> base_pose;  // 3·m, base order: what replaying it submits
  // 3·n, session order: rest + the decoded deltas, deformed at full detail
  // (T = 0's direct recovery) as the session's frames are.
  std::vector<float> positions;
  float max_error = 0.0f;  // largest |decoded − exact| coordinate error of `positions`

  std::size_t vertex_count() const { return positions.size() / 3; }
};

}  // namespace filigree
