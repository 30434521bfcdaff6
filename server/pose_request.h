#pragma once
// A DriveRequest (from Drive or SubmitPose) merged into its session.

#include <cstddef>
#include <cstdint>
#include <string>

#include "filigree/v1/filigree.pb.h"

namespace filigree::server {

class Session;

// The longest client_name a change may carry: names are kept in frames'
// changes, the history and presence.
inline constexpr std::size_t kMaxClientName = 256;
// Throws PoseError for a longer one.
void check_client_name(const std::string& name);

// Merges `r`'s pose into `session` as `driver`'s (0: a unary call): its
// positions (full or partial) or its joints, not both; a keyframe request
// alone asks for a keyframe. Throws PoseError (nothing changes) for a pose
// the session refuses, and what Session::submit throws.
void submit_pose(Session& session, std::uint64_t driver, const v1::DriveRequest& r);

}  // namespace filigree::server
