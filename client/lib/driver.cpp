#include "filigree/driver.h"

#include <stdexcept>

#include "detail_switch.h"
#include "filigree/call_metadata.h"
#include "pose_check.h"

namespace filigree {
namespace {

// Acknowledged requests kept for send() to reuse.
constexpr std::size_t kSpareRequests = 2;

}  // namespace

Driver::Driver(v1::Filigree::Stub& stub, const std::string& session_id, const std::string& token,
               std::string client_name, const DriveOptions& options, Routing routing, Reconnect reconnect,
               std::chrono::milliseconds call_timeout)
    : stub_(stub), session_id_(session_id), token_(token), client_name_(std::move(client_name)), routing_(routing),
      call_timeout_(call_timeout), reconnect_(std::move(reconnect)),
      detail_(std::make_unique<DetailSwitch>(options.max_vertices)) {
  std::unique_lock lock(mutex_);
  open(lock);
}

Driver::~Driver() {
  {
    std::lock_guard lock(mutex_);
    if (status_) return;
  }
  // Unfinished: cancel so the drain below cannot wait on the server.
  cancel();
  finish();
}

void Driver::open(std::unique_lock<std::mutex>&) {
  auto context = std::make_unique<grpc::ClientContext>();
  set_session_metadata(*context, session_id_, token_, routing_);
  // With poses to re-send, the metadata goes with the first of them: Drive()
  // then returns at once instead of waiting for a connection (seconds to an
  // unreachable host) while holding mutex_, and so every send(). Without,
  // the call must start now: a refused token shows before the first pose.
  if (!unacknowledged_.empty() || writes_done_) context->set_initial_metadata_corked(true);
  grpc::ClientContext* raw = context.get();
  {
    // Installed before the call starts, so a cancel() meanwhile reaches it.
    std::lock_guard lock(cancel_mutex_);
    stream_.reset();  // the old stream goes before its context
    context_ = std::move(context);
    if (cancelled_) context_->TryCancel();
  }
  stream_ = stub_.Drive(raw);
  broken_ = false;
  detail_->opened();
  // In order: the server merges them as they would have been. The first
  // opens the stream at the latest budget (set_detail's, if it changed).
  const std::uint32_t max_vertices = detail_->max_vertices();
  for (v1::DriveRequest& pose : unacknowledged_) {
    pose.set_max_vertices(max_vertices);
    if (!stream_->Write(pose)) {
      broken_ = true;
      return;
    }
  }
  if (writes_done_ && !stream_->WritesDone()) broken_ = true;
}

bool Driver::write() {
  // Every request names the session and the client: the first one opens the
  // driver on the server, and the name is reported with each change.
  request_.set_session_id(session_id_);
  request_.set_client_name(client_name_);
  request_.set_gesture_id(gesture_.load());
  request_.set_frame_format(v1::FRAME_FORMAT_CHUNKED);
  // Read from a stream's first request only; on every one, so that the
  // first of a reopened stream carries it too.
  request_.set_max_vertices(detail_->max_vertices());
  std::lock_guard lock(mutex_);
  if (status_ || writes_done_) return false;
  if (!broken_ && !stream_->Write(request_)) broken_ = true;
  if (reconnect_.enabled()) {
    // A full pose replaces every position before it, so the position poses
    // it follows need no re-sending (joint poses stay: they are merged apart).
    const bool full_positions = !request_.has_joints() && request_.indices_size() == 0;
    if (full_positions) std::erase_if(unacknowledged_, [](const v1::DriveRequest& r) { return !r.has_joints(); });
    if (unacknowledged_.size() >= kMaxUnacknowledged) unacknowledged_.pop_front();  // the bound (driver.h)
    // Kept by moving, and request_ continues with an acknowledged message's
    // buffers: no pose-sized allocation per send once warm.
    unacknowledged_.push_back(std::move(request_));
    if (!spare_.empty()) {
      request_ = std::move(spare_.back());
      spare_.pop_back();
    }
  }
  // With reconnection, a pose sent into a broken stream waits for the next one.
  return !broken_ || reconnect_.enabled();
}

bool Driver::send(std::uint64_t pose_id, std::span<const float> positions) {
  check_positions("send", {}, positions);
  request_.set_pose_id(pose_id);
  request_.clear_indices();
  request_.clear_joints();
  request_.mutable_positions()->Assign(positions.begin(), positions.end());
  return write();
}

bool Driver::send_partial(std::uint64_t pose_id, std::span<const std::uint32_t> indices,
                          std::span<const float> positions) {
  if (positions.size() != 3 * indices.size())
    throw std::invalid_argument("send_partial: " + std::to_string(positions.size()) + " coordinates for " +
                                std::to_string(indices.size()) + " indices (3 per index expected)");
  check_positions("send_partial", indices, positions);
  request_.set_pose_id(pose_id);
  request_.clear_joints();
  request_.mutable_indices()->Assign(indices.begin(), indices.end());
  request_.mutable_positions()->Assign(positions.begin(), positions.end());
  return write();
}

bool Driver::send_joints(std::uint64_t pose_id, v1::JointPose::Space space, std::span<const std::uint32_t> joints,
                         std::span<const float> values) {
  const std::size_t per_joint = space == v1::JointPose::SPACE_MODEL_MATRIX ? 16 : 10;
  if (!joints.empty() && values.size() != per_joint * joints.size())
    throw std::invalid_argument("send_joints: " + std::to_string(values.size()) + " values for " +
                                std::to_string(joints.size()) + " joints (" + std::to_string(per_joint) +
                                " per joint expected)");
  if (joints.empty() && values.size() % per_joint != 0)
    throw std::invalid_argument("send_joints: " + std::to_string(values.size()) + " values is not a multiple of " +
                                std::to_string(per_joint));
  check_joints("send_joints", space, joints, values);
  request_.set_pose_id(pose_id);
  request_.clear_indices();
  request_.clear_positions();
  v1::JointPose& pose = *request_.mutable_joints();
  pose.set_space(space);
  pose.mutable_joint_indices()->Assign(joints.begin(), joints.end());
  pose.mutable_values()->Assign(values.begin(), values.end());
  return write();
}

std::optional<v1::Frame> Driver::read() {
  while (true) {
    grpc::ClientReaderWriter<v1::DriveRequest, v1::Frame>* stream;
    {
      std::lock_guard lock(mutex_);
      if (status_) return std::nullopt;
      stream = stream_.get();  // replaced only by this thread (open, below)
    }
    v1::Frame frame;
    if (stream->Read(&frame)) {
      if (frame.has_refused()) {
        // A pose the server refused (the stream goes on): never resent, and
        // told by last_refusal(); no frame to return.
        std::lock_guard lock(mutex_);
        std::erase_if(unacknowledged_, [&](const v1::DriveRequest& r) { return r.pose_id() == frame.pose_id(); });
        last_refusal_ = Refusal{frame.pose_id(), frame.refused().message()};
        continue;
      }
      // Only a frame that answers a pose shows the link works: a server that
      // sends its current frame and fails again must not reset the backoff.
      if (frame.pose_id() != 0) reconnect_.reset();
      detail_->observe(frame);
      std::lock_guard lock(mutex_);
      while (!unacknowledged_.empty() && unacknowledged_.front().pose_id() <= frame.pose_id()) {
        if (spare_.size() < kSpareRequests) spare_.push_back(std::move(unacknowledged_.front()));
        unacknowledged_.pop_front();
      }
      return frame;
    }
    grpc::Status status;
    {
      // No write is in flight while the lock is held: gRPC's Finish may follow.
      std::lock_guard lock(mutex_);
      broken_ = true;
      status = stream_->Finish();
    }
    if (auto ended = reconnect_.wait_to_reconnect(status, cancel_mutex_, cancelled_cv_, cancelled_)) {
      std::lock_guard lock(mutex_);
      status_ = std::move(*ended);
      return std::nullopt;
    }
    std::unique_lock lock(mutex_);
    open(lock);
  }
}

bool Driver::writes_done() {
  std::lock_guard lock(mutex_);
  if (writes_done_) return !status_;
  writes_done_ = true;
  if (status_) return false;
  // A broken stream's successor sends it (open()).
  if (!broken_ && !stream_->WritesDone()) broken_ = true;
  return !broken_ || reconnect_.enabled();
}

std::uint32_t Driver::set_detail(std::uint32_t max_vertices) {
  return detail_->set(stub_, session_id_, token_, routing_, call_timeout_, max_vertices);
}

void Driver::cancel() {
  std::lock_guard lock(cancel_mutex_);
  cancelled_ = true;
  if (context_) context_->TryCancel();
  cancelled_cv_.notify_all();
}

std::size_t Driver::unacknowledged() const {
  std::lock_guard lock(mutex_);
  return unacknowledged_.size();
}

grpc::Status Driver::finish() {
  writes_done();
  // gRPC's rule: read until Read() fails, then Finish() (read() does both).
  while (read()) {
  }
  std::lock_guard lock(mutex_);
  return *status_;
}

}  // namespace filigree
