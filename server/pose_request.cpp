#include "server/pose_request.h"

#include "server/session.h"

namespace filigree::server {

void check_client_name(const std::string& name) {
  if (name.size() > kMaxClientName)
    throw PoseError("client_name has " + std::to_string(name.size()) + " bytes; at most " + std::to_string(kMaxClientName));
}

void submit_pose(Session& session, std::uint64_t driver, const v1::DriveRequest& r) {
  if (r.request_keyframe() && r.positions().empty() && r.indices().empty() && !r.has_joints())
    return session.request_keyframe();  // only the keyframe request: no pose to merge
  check_client_name(r.client_name());
  const PoseOrigin origin{driver, r.client_name(), r.pose_id(), r.request_keyframe(), r.gesture_id()};
  if (r.has_joints()) {
    if (!r.positions().empty() || !r.indices().empty())
      throw PoseError("a pose gives positions or joints, not both");
    return session.submit_joints(origin, r.joints());
  }
  session.submit(origin, {r.indices().data(), static_cast<std::size_t>(r.indices().size())},
                 {r.positions().data(), static_cast<std::size_t>(r.positions().size())});
}

}  // namespace filigree::server
