#include "server/session.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <tuple>
#include <utility>

#include <spdlog/spdlog.h>

#include "codec/delta_codec.h"
#include "codec/delta_quantization.h"
#include "codec/draco_writer.h"
#include "codec/keyed_deltas.h"
#include "hierarchy/cut_state.h"
#include "hierarchy/detail_level.h"
#include "hierarchy/hierarchy.h"
#include "runtime/deformer.h"
#include "runtime/deformer_model.h"
#include "runtime/handle_solver.h"
#include "runtime/pose.h"
#include "server/secret.h"
#include "server/session_info_wire.h"
#include "server/state/session_store.h"
#include "skinning/animation_clip.h"
#include "skinning/rig_file.h"
#include "skinning/skinning.h"

namespace filigree::server {
namespace {


v1::Skeleton skeleton_info(const Rig& rig) {
  v1::Skeleton out;
  for (const Joint& j : rig.joints) {
    v1::Skeleton::Joint& joint = *out.add_joints();
    joint.set_name(j.name);
    joint.set_parent(j.parent);
    const JointTransform& t = j.rest;
    for (const double v : {t.translation.x(), t.translation.y(), t.translation.z(), t.rotation.x(), t.rotation.y(),
                           t.rotation.z(), t.rotation.w(), t.scale.x(), t.scale.y(), t.scale.z()})
      joint.add_rest(static_cast<float>(v));
  }
  for (const AnimationClip& c : rig.clips) {
    v1::Skeleton::Clip& clip = *out.add_clips();
    clip.set_name(c.name);
    clip.set_duration_seconds(c.duration());
  }
  return out;
}

using Clock = std::chrono::steady_clock;

DeformerOptions deformer_options(const v1::SessionOptions& o) {
  DeformerOptions d;
  d.threshold = o.whole_mesh() ? DeformerOptions::kInfinity : o.threshold();
  d.regions_budget_ms = o.whole_mesh() ? 0.0 : o.regions_budget_ms();
  // One compute thread per session: sessions run side by side.
  d.threads = 1;
  return d;
}

}  // namespace

Session::Session(SessionRecord record, std::shared_ptr<const SessionAssets> assets, FrameScheduler& scheduler,
                 Journal journal, HistoryLimits history_limits)
    : assets_(std::move(assets)), scheduler_(scheduler), lane_(scheduler.lane()),
      encoder_(assets_->hierarchy().rest_positions, frame_encoder_options(record.options, *assets_)),
      history_(assets_->hierarchy().base_vertices.size(), history_limits), record_(std::move(record)),
      last_activity_(Clock::now()), journal_(std::move(journal)) {
  const Hierarchy& h = assets_->hierarchy();
  if (!record_.history.empty()) {
    try {
      history_ = EditHistory::deserialize(record_.history, h.base_vertices.size(), history_limits);
    } catch (const std::exception& e) {  // the session comes back without its history rather than not at all
      spdlog::warn("session={} event=history_not_restored error=\"{}\"", record_.id, e.what());
    }
    record_.history = {};
  }
  const v1::BaseMesh& base = assets_->base;
  if (record_.pose.size() != 3 * h.base_vertices.size()) record_.pose.assign(base.positions().begin(), base.positions().end());
  if (!record_.rig.empty()) {
    auto rig = std::make_unique<Rig>(deserialize_rig(record_.rig, "session " + record_.id + " rig"));
    if (rig->vertex_count() != h.base_vertices.size())
      throw RigError("session " + record_.id + " rig: " + std::to_string(rig->vertex_count()) + " vertices for a base of " +
                     std::to_string(h.base_vertices.size()));
    joint_pose_ = std::make_unique<SkeletonPose>(SkeletonPose::rest(*rig));
    skeleton_info_ = skeleton_info(*rig);
    rig_ = std::move(rig);
  }
  assigned_version_ = record_.version;
  // Handles carried over a restart or a failover, in the order they were set
  // (the newest per vertex wins, as it did there). The live copy is handles_.
  for (const SessionHandle& kept : record_.handles) {
    const Vec3 target(kept.target[0], kept.target[1], kept.target[2]);
    if (kept.vertex >= h.vertex_count() || !target.allFinite())
      throw std::runtime_error("session " + record_.id + " record: handle of vertex " + std::to_string(kept.vertex) +
                               " is out of range or not finite");
    handles_[kept.vertex].push_back({target, kept.client, ++handle_stamp_});
  }
  // Solved handles are in the pose already: solving them again would move it
  // (the solve starts from the current pose), which the old process would not have done.
  handles_dirty_ = record_.handles_pending && !handles_.empty();
  record_.handles.clear();
  record_.handles_pending = false;

  try {
    deformer_ = std::make_unique<Deformer>(assets_->model, deformer_options(record_.options));
  } catch (const HierarchyError& e) {
    // A recorded finite T on a hierarchy that cannot run one (a cache file
    // replaced since): the session comes back at T = 0 rather than not at all.
    spdlog::warn("session={} event=threshold_reset error=\"{}\"", record_.id, e.what());
    record_.options.set_threshold(0.0);
    record_.options.set_whole_mesh(false);
    deformer_ = std::make_unique<Deformer>(assets_->model, deformer_options(record_.options));
  }
  // The adaptive cut is not a function of the pose: it moves a bounded number
  // of nodes a frame by scores it remembers. Restored, the frame below (of
  // the recorded pose) is the old process's last one, and the next frames
  // are the ones it would have computed; started full, they would differ by
  // more than a frame's quantization error until the cut adapted again.
  if (!record_.cut.empty()) {
    try {
      deformer_->restore_cut(record_.cut);
    } catch (const std::invalid_argument& e) {  // a record of another hierarchy build: start full
      spdlog::warn("session={} event=cut_not_restored error=\"{}\"", record_.id, e.what());
    }
    record_.cut = {};  // record() takes the live cut
  }
  handle_solver_ = std::make_unique<HandleSolver>(h.base_mesh());
  // The current frame exists from the start: the rest mesh, or after a
  // restart the latest pose, under the version it had. Computed and encoded
  // here, on the caller's thread.
  encode_first_frame();
}

Session::~Session() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  scheduler_.drain(*lane_);
}

Role Session::authorize(const std::string& token) const {
  // Both compared, in constant time: which one matched does not show either.
  const bool editor = same_secret(token, record_.editor_token), viewer = same_secret(token, record_.viewer_token);
  return editor ? Role::kEditor : viewer ? Role::kViewer : Role::kNone;
}

void Session::touch() { last_activity_ = Clock::now(); }

std::size_t Session::vertex_count() const { return assets_->hierarchy().vertex_count(); }

void Session::submit(const PoseOrigin& origin, std::span<const std::uint32_t> indices, std::span<const float> positions) {
  const std::size_t m = assets_->hierarchy().base_vertices.size();
  const std::size_t count = indices.empty() ? m : indices.size();
  if (positions.size() != 3 * count)
    throw PoseError("pose has " + std::to_string(positions.size()) + " coordinates for " + std::to_string(count) +
                    (indices.empty() ? " base vertices (a full pose)" : " indices") + "; expected " + std::to_string(3 * count));
  for (std::size_t i = 0; i < indices.size(); ++i)
    if (indices[i] >= m)
      throw PoseError("pose index " + std::to_string(indices[i]) + " at position " + std::to_string(i) +
                      " is out of range: the base mesh has " + std::to_string(m) + " vertices");
  for (std::size_t i = 0; i < positions.size(); ++i) {
    if (!std::isfinite(positions[i])) throw PoseError("pose coordinate " + std::to_string(i) + " is not finite (NaN or Inf)");
    check_reach(positions[i], "pose coordinate", i);
  }
  merge(origin, indices, positions, /*skinned=*/false);
}

void Session::check_reach(double coordinate, const char* what, std::size_t index) const {
  if (std::abs(coordinate) <= assets_->pose_reach) return;  // every coordinate of every pose: no message built
  std::ostringstream message;
  message << what << ' ' << index << " is " << coordinate << ", beyond this mesh's reach of ±" << assets_->pose_reach << " ("
          << kPoseReachSizes << " times its size from where it lies)";
  throw PoseError(message.str());
}

void Session::merge(const PoseOrigin& origin,
                    std::span<const std::uint32_t> indices, std::span<const float> positions, bool skinned) {
  const std::size_t count = indices.empty() ? positions.size() / 3 : indices.size();
  // A unary change is answered when this returns: journaled now. A streamed
  // pose is answered by its frame, journaled before it is published.
  const bool journal_now = journal_ && (origin.driver == 0 || journal_.every_merge);
  std::uint64_t seq;
  SessionProgress progress;
  {
    std::lock_guard lock(mutex_);
    if (evicted_) throw_evicted();
    if (closed_) return;
    // Handles edit on top of the skeleton: solved again from the new skinned base.
    if (skinned && !handles_.empty()) handles_dirty_ = true;
    history_.record_pose({origin.client_name, origin.gesture, unix_seconds(), assigned_version_, origin.driver},
                         v1::HistoryEntry::KIND_POSE, indices, record_.pose, positions);
    for (std::size_t i = 0; i < count; ++i) {
      const std::size_t v = indices.empty() ? i : indices[i];
      for (int k = 0; k < 3; ++k) record_.pose[3 * v + k] = positions[3 * i + k];
    }
    if (origin.driver != 0) latest_pose_of_driver_[origin.driver] = origin.pose_id;  // 0: unary, no stream to answer
    // Under the lock of the merge: the frame that takes this pose is the keyframe.
    if (origin.keyframe) keyframe_requested_ = true;
    v1::Change& change = changes_[origin.client_name];
    change.set_client_name(origin.client_name);
    change.set_pose_id(origin.pose_id);
    std::vector<bool>& touched = touched_[origin.client_name];
    touched.resize(record_.pose.size() / 3);
    std::uint32_t newly = 0;
    for (std::size_t i = 0; i < count; ++i) {
      const std::size_t v = indices.empty() ? i : indices[i];
      newly += touched[v] ? 0 : 1;
      touched[v] = true;
    }
    change.set_vertex_count(change.vertex_count() + newly);
    publish_presence_locked(/*paced=*/true);
    seq = ++journal_seq_;
    if (journal_now) progress = progress_with_change_locked();
    pending_ = true;
    maybe_compute_locked();
    touch();
  }
  if (journal_now) journal(progress, seq);
}

void Session::subscribe(const std::shared_ptr<FrameSink>& sink, std::optional<std::uint64_t> after_version) {
  std::shared_ptr<const PublishedFrame> now;
  {
    std::lock_guard lock(mutex_);
    if (closed_) {
      if (evicted_)
        sink->close(false, "session " + record_.id + " left this server's memory as the stream opened: reconnect");
      else
        sink->close(true, {});
      return;
    }
    sinks_.push_back(sink);
    if (current_ && (!after_version || current_->frame.version() > *after_version)) now = current_;
    compute_if_level_missing_locked();
    touch();
  }
  // A single-buffer subscriber of a frame made without that buffer: the
  // frame transcoded (no new frame, no new version).
  if (now && sink->format() == v1::FRAME_FORMAT_SINGLE && !now->single) {
    try {
      now = with_single(now);
    } catch (const std::exception& e) {  // the next frame carries the buffer
      spdlog::error("session={} event=transcode_failed error=\"{}\"", record_.id, e.what());
      now.reset();
    }
  }
  if (now) sink->offer(now);
}

void Session::request_keyframe() {
  std::lock_guard lock(mutex_);
  keyframe_requested_ = true;
  pending_ = true;
  maybe_compute_locked();
}

std::uint32_t Session::level_for(std::uint32_t max_vertices) const {
  return detail_level_vertices(max_vertices, assets_->hierarchy().base_vertices.size(), assets_->hierarchy().vertex_count());
}

std::vector<std::uint32_t> Session::wanted_levels_locked() const {
  const std::uint32_t full = static_cast<std::uint32_t>(assets_->hierarchy().vertex_count());
  std::vector<std::uint32_t> levels;
  for (const auto& w : sinks_)
    if (const auto sink = w.lock()) {
      const std::uint32_t level = sink->level();
      if (level != 0 && level != full && std::find(levels.begin(), levels.end(), level) == levels.end()) levels.push_back(level);
    }
  return levels;
}

void Session::compute_if_level_missing_locked() {
  bool missing = false;
  for (std::uint32_t level : wanted_levels_locked()) {
    if (current_ && current_->at_level(level)) continue;
    if (assets_->levels->find(level)) {
      missing = true;
      continue;
    }
    // Built on a task of its own (up to a second at 1.25M vertices), not in
    // a compute, so that no driver's frame waits for it; then a frame with it.
    if (!levels_building_.insert(level).second) continue;
    scheduler_.post(*lane_, [this, level] {
      try {
        assets_->levels->get(level);
      } catch (const std::exception& e) {
        spdlog::error("session={} event=level_failed level={} error=\"{}\"", record_.id, level, e.what());
      }
      std::lock_guard lock(mutex_);
      levels_building_.erase(level);
      pending_ = true;
      maybe_compute_locked();
    });
  }
  if (missing) {
    pending_ = true;
    maybe_compute_locked();
  }
}

std::optional<std::uint32_t> Session::set_detail(std::uint64_t stream_id, std::uint32_t max_vertices) {
  const std::uint32_t level = level_for(max_vertices);
  std::shared_ptr<FrameSink> sink;
  std::shared_ptr<const PublishedFrame> now;
  {
    std::lock_guard lock(mutex_);
    for (const auto& w : sinks_)
      if (auto s = w.lock(); s && s->stream_id() == stream_id) sink = std::move(s);
    if (!sink) return std::nullopt;
    sink->switch_level(level);
    now = current_;
    compute_if_level_missing_locked();
    touch();
  }
  // The current frame at once if it has the level; else the frame computing
  // now for it.
  if (now && now->at_level(level)) sink->offer(now);
  return level;
}

void Session::unsubscribe(const FrameSink* sink) {
  std::lock_guard lock(mutex_);
  std::erase_if(sinks_, [&](const std::weak_ptr<FrameSink>& w) {
    const auto s = w.lock();
    return !s || s.get() == sink;
  });
  touch();
}

void Session::driver_left(std::uint64_t driver) {
  std::lock_guard lock(mutex_);
  latest_pose_of_driver_.erase(driver);
}

std::size_t Session::set_handles(const std::string& client_name, const std::vector<std::pair<Index, Vec3>>& handles,
                                 std::uint64_t gesture) {
  for (const auto& [v, target] : handles) {
    if (v >= assets_->hierarchy().vertex_count())
      throw PoseError("handle vertex " + std::to_string(v) + " is out of range: the mesh has " +
                      std::to_string(assets_->hierarchy().vertex_count()) + " vertices");
    if (!target.allFinite()) throw PoseError("handle target of vertex " + std::to_string(v) + " is not finite");
    for (int k = 0; k < 3; ++k) check_reach(target[k], "handle target of vertex", v);
  }
  std::size_t count = 0;
  std::uint64_t seq;
  SessionProgress progress;
  {
    std::lock_guard lock(mutex_);
    if (evicted_) throw_evicted();
    if (closed_) return 0;
    HandleSet before;
    for (auto it = handles_.begin(); it != handles_.end();) {
      for (const HandleEntry& e : it->second)
        if (e.client == client_name) before.emplace_back(it->first, e.target);
      std::erase_if(it->second, [&](const HandleEntry& e) { return e.client == client_name; });
      it = it->second.empty() ? handles_.erase(it) : std::next(it);
    }
    for (const auto& [v, target] : handles) handles_[v].push_back({target, client_name, ++handle_stamp_});
    handles_origin_ = {client_name, gesture, unix_seconds(), assigned_version_};
    history_.record_handles(handles_origin_, before, handles);
    count = handles_.size();
    v1::Change& change = changes_[client_name];
    change.set_client_name(client_name);
    change.set_vertex_count(change.vertex_count() + static_cast<std::uint32_t>(handles.size()));
    handles_dirty_ = true;
    publish_presence_locked(/*paced=*/true);
    // Journaled like a pose: a session that moves keeps every client's handles.
    seq = ++journal_seq_;
    if (journal_) progress = progress_with_change_locked();
    pending_ = true;
    maybe_compute_locked();
    touch();
  }
  journal(progress, seq);
  return count;
}

v1::SessionHandles Session::handles() const {
  std::vector<SessionHandle> kept;
  v1::SessionHandles out;
  {
    std::lock_guard lock(mutex_);
    kept = handles_locked();
    out.set_version(record_.version);
  }
  // Oldest first is the order each client set its own in (stamps rise within a call).
  std::map<std::string, std::vector<const SessionHandle*>> by_client;
  for (const SessionHandle& h : kept) by_client[h.client].push_back(&h);
  for (const auto& [client, handles] : by_client) {
    v1::SessionHandles::Participant& p = *out.add_participants();
    p.set_client_name(client);
    for (const SessionHandle* h : handles) {
      v1::Handle& w = *p.add_handles();
      w.set_vertex(h->vertex);
      w.set_x(h->target[0]);
      w.set_y(h->target[1]);
      w.set_z(h->target[2]);
    }
  }
  return out;
}

bool Session::threshold_needs_preparation(double threshold, bool whole_mesh) const {
  const DeformerModel& m = *assets_->model;
  return whole_mesh || (threshold > 0.0 && !(m.node_graph_derived() && m.optimisation_data_derived()));
}

std::uint64_t Session::set_threshold(double threshold, bool whole_mesh, const std::string* author) {
  if (whole_mesh || threshold > 0.0) {
    // A finite T needs the hierarchy's node graph, which loading does not
    // check (hierarchy/node_graph.h): derive it now (once per mesh) so that
    // a hierarchy that cannot run one is refused here, not frame after frame.
    (void)assets_->model->node_graph();
    // And region optimisation's data (0.65 s at 1.25M): built here, not by
    // the first frame on a worker every session's frames share.
    (void)assets_->model->laplacian();
  }
  std::unique_ptr<Deformer> warm;
  if (whole_mesh) {
    // T = ∞ factorises the whole mesh (2 s at 435k vertices), a factor every
    // session of the mesh shares (RegionFactors): a deformer makes it here
    // by solving the rest pose once (T = ∞'s regions do not depend on the
    // pose) and holds it until this session's frame at T = ∞ has found it,
    // so that frame, on a worker every session's frames share, only solves.
    DeformerOptions o;
    o.threshold = DeformerOptions::kInfinity;
    o.threads = 1;
    warm = std::make_unique<Deformer>(assets_->model, o);
    const Hierarchy& h = assets_->hierarchy();
    Pose rest;
    rest.positions.reserve(h.base_vertices.size());
    for (Index v : h.base_vertices) rest.positions.push_back(h.rest_positions[v]);
    std::vector<Vec3> out(h.vertex_count());
    (void)warm->deform(rest, out);
  }
  std::uint64_t seq, accepted;
  SessionProgress progress;
  {
    std::lock_guard lock(mutex_);
    if (evicted_) throw_evicted();
    // Frames take their version and options together, under this lock.
    accepted = assigned_version_;
    if (author)
      history_.record_threshold({*author, 0, unix_seconds(), assigned_version_},
                                record_.options.whole_mesh() ? DeformerOptions::kInfinity : record_.options.threshold(),
                                whole_mesh ? DeformerOptions::kInfinity : threshold);
    record_.options.set_threshold(threshold);
    record_.options.set_whole_mesh(whole_mesh);
    pending_threshold_ = whole_mesh ? DeformerOptions::kInfinity : threshold;
    warm.swap(warm_);  // an older one, if any, goes after the lock
    seq = ++journal_seq_;
    if (journal_) progress = progress_with_change_locked();
    pending_ = true;
    maybe_compute_locked();
    touch();
  }
  journal(progress, seq);
  return accepted;
}

void Session::close() {
  std::vector<std::shared_ptr<FrameSink>> sinks;
  std::vector<std::shared_ptr<PresenceSink>> presence;
  {
    std::lock_guard lock(mutex_);
    closed_ = true;
    stopping_ = true;
    for (const auto& w : sinks_)
      if (auto s = w.lock()) sinks.push_back(s);
    sinks_.clear();
    for (const auto& w : presence_sinks_)
      if (auto s = w.lock()) presence.push_back(s);
    presence_sinks_.clear();
  }
  for (const auto& s : sinks) s->close(true, {});
  for (const auto& s : presence) s->close(true, {});
}

bool Session::evict_if_unused() {
  std::lock_guard lock(mutex_);
  for (const auto& w : sinks_)
    if (!w.expired()) return false;
  for (const auto& w : presence_sinks_)
    if (!w.expired()) return false;
  evicted_ = closed_ = stopping_ = true;
  return true;
}

void Session::throw_evicted() const {
  throw StoreUnavailable("session " + record_.id + " left this server's memory while the request ran: retry");
}

void Session::close_streams(const std::string& why) {
  std::vector<std::shared_ptr<FrameSink>> sinks;
  std::vector<std::shared_ptr<PresenceSink>> presence;
  {
    std::lock_guard lock(mutex_);
    for (const auto& w : sinks_)
      if (auto s = w.lock()) sinks.push_back(s);
    sinks_.clear();
    for (const auto& w : presence_sinks_)
      if (auto s = w.lock()) presence.push_back(s);
    presence_sinks_.clear();
  }
  for (const auto& s : sinks) s->close(false, why);
  for (const auto& s : presence) s->close(false, why);
}

std::string Session::failure() const {
  std::lock_guard lock(mutex_);
  return failure_;
}

SessionProgress Session::progress_with_change_locked() const {
  // The frame that will show a change made now: the next, or the one after the one computing.
  return {record_.options, record_.pose, record_.version + in_flight_locked() + 1, handles_locked(),
          handles_pending_locked(), {}};
}

std::vector<SessionHandle> Session::handles_locked() const {
  // Oldest first, so that a restore gives them stamps in the same order.
  std::vector<std::pair<std::uint64_t, SessionHandle>> stamped;
  for (const auto& [v, entries] : handles_)
    for (const HandleEntry& e : entries)
      stamped.push_back({e.stamp,
                         {v, e.client, {static_cast<float>(e.target.x()), static_cast<float>(e.target.y()), static_cast<float>(e.target.z())}}});
  std::sort(stamped.begin(), stamped.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  std::vector<SessionHandle> out;
  out.reserve(stamped.size());
  for (auto& [stamp, handle] : stamped) out.push_back(std::move(handle));
  return out;
}

void Session::journal(const SessionProgress& progress, std::uint64_t seq) {
  if (!journal_) return;
  std::lock_guard lock(journal_mutex_);
  if (seq <= journaled_seq_) return;  // a later snapshot, with this change, is stored
  journal_.write(progress);
  journaled_seq_ = seq;
}

grpc::ByteBuffer Session::overlays_wire() {
  std::shared_ptr<const SerializedOnce> recent;
  {
    std::lock_guard lock(mutex_);
    recent = overlays_;
    overlays_wanted_until_ = Clock::now() + std::chrono::seconds(5);
    if (!recent) {
      pending_ = true;  // recompute the current pose once, with overlays
      maybe_compute_locked();
    }
    touch();
  }
  if (recent) return recent->bytes();  // serialized by the first caller, outside the lock
  const grpc::Slice none;                // an empty Overlays: ready == false
  return grpc::ByteBuffer(&none, 1);
}

v1::SessionInfo Session::info(std::size_t inline_rest_most) const {
  // The meshes are immutable: built and copied outside the session's lock.
  v1::SessionInfo info = own_info();
  *info.mutable_base() = assets_->base;
  if (assets_->info_wire->rest_body().size() + ids_wire().size() > inline_rest_most) {
    const Hierarchy& h = assets_->hierarchy();
    v1::RestMesh& rest = *info.mutable_rest();
    rest.set_vertex_count(static_cast<std::uint32_t>(h.vertex_count()));
    rest.set_in_parts(true);
    rest.set_face_count(static_cast<std::uint32_t>(h.original_face_count()));
    return info;
  }
  *info.mutable_rest() = rest_mesh_message(assets_->hierarchy());
  info.mutable_rest()->mutable_uploaded_ids()->Add(record_.uploaded_ids.begin(), record_.uploaded_ids.end());
  return info;
}

const grpc::Slice& Session::ids_wire() const {
  // The ids never change after the session is made (record_.uploaded_ids is written only then).
  std::call_once(ids_wire_once_, [this] { ids_wire_ = uploaded_ids_field(record_.uploaded_ids); });
  return ids_wire_;
}

v1::SessionInfo Session::own_info() const {
  v1::SessionInfo info;
  std::lock_guard lock(mutex_);
  info.set_session_id(record_.id);
  info.set_mesh_hash(record_.hierarchy_key.substr(0, 16));
  *info.mutable_options() = record_.options;
  info.set_version(record_.version);
  if (rig_) *info.mutable_skeleton() = skeleton_info_;
  return info;
}

grpc::ByteBuffer Session::info_wire(std::size_t inline_rest_most, std::optional<std::uint64_t> version) const {
  v1::SessionInfo own = own_info();
  if (version) own.set_version(*version);
  return session_info_wire(own, *assets_->info_wire, ids_wire(), inline_rest_most);
}

void Session::describe(v1::ListSessionsResponse::Entry& entry) const {
  {
    std::lock_guard lock(mutex_);
    entry.set_session_id(record_.id);
    entry.set_mesh_hash(record_.hierarchy_key.substr(0, 16));
    entry.set_vertex_count(static_cast<std::uint32_t>(assets_->hierarchy().vertex_count()));
    entry.set_base_vertex_count(static_cast<std::uint32_t>(assets_->base.original_ids_size()));
    entry.set_version(record_.version);
  }
  // Each takes mutex_ itself.
  entry.set_drivers(static_cast<std::uint32_t>(drivers()));
  entry.set_watchers(static_cast<std::uint32_t>(subscriber_count()));
  std::lock_guard lock(mutex_);
  for (std::uint32_t level : wanted_levels_locked()) {
    v1::DetailLevelUse& use = *entry.add_levels();
    use.set_vertex_count(level);
    for (const auto& w : sinks_)
      if (const auto sink = w.lock(); sink && sink->level() == level) use.set_streams(use.streams() + 1);
    if (const auto it = level_frames_encoded_.find(level); it != level_frames_encoded_.end()) use.set_frames_encoded(it->second);
  }
}

grpc::ByteBuffer Session::state_wire(v1::FrameFormat format) {
  v1::SessionState own;
  std::shared_ptr<const PublishedFrame> frame;
  {
    // The version, the pose and the frame of one moment.
    std::lock_guard lock(mutex_);
    own.set_version(record_.version);
    own.mutable_pose()->Add(record_.pose.begin(), record_.pose.end());
    frame = current_;
  }
  std::string head = own.SerializeAsString();
  // SessionState.frame and .keyframe.
  constexpr std::uint32_t kFrame = 3, kKeyframe = 4;
  if (!frame) return message_with_frames(std::move(head), {});
  if (format == v1::FRAME_FORMAT_SINGLE) {
    if (!frame->single) frame = with_single(frame);  // the same frame, transcoded
    return message_with_frames(std::move(head), {{kFrame, &frame->single_bytes()}});
  }
  if (frame->keyframe) return message_with_frames(std::move(head), {{kFrame, &frame->frame_bytes()}, {kKeyframe, &frame->keyframe->frame_bytes()}});
  return message_with_frames(std::move(head), {{kFrame, &frame->frame_bytes()}});
}

bool Session::needs_single(v1::FrameFormat format) const {
  if (format != v1::FRAME_FORMAT_SINGLE) return false;
  std::lock_guard lock(mutex_);
  return current_ && !current_->single;
}

SessionRecord Session::record() const {
  SessionProgress p = progress();
  SessionRecord r;
  {
    // What progress does not carry never changes after construction.
    std::lock_guard lock(mutex_);
    r = record_;
  }
  r.cut = std::exchange(p.cut, {});  // the live cut, even an empty one
  apply_progress(p, r);              // which p, now without a cut, keeps
  return r;
}

SessionProgress Session::progress() const {
  // No frame may change the cut between its snapshot and the copy of the
  // pose; the O(nodes) snapshot is taken outside mutex_ (it blocks no call).
  std::lock_guard cut_lock(cut_mutex_);
  CutSnapshot cut = deformer_->cut_snapshot();
  std::lock_guard lock(mutex_);
  return {record_.options, record_.pose, record_.version, handles_locked(), handles_pending_locked(), std::move(cut)};
}

std::shared_ptr<const PublishedFrame> Session::current_frame() const {
  std::lock_guard lock(mutex_);
  return current_;
}

std::size_t Session::subscriber_count() const {
  std::lock_guard lock(mutex_);
  std::size_t n = 0;
  for (const auto& w : sinks_) n += w.expired() ? 0 : 1;
  return n;
}

double Session::idle_seconds() const {
  std::lock_guard lock(mutex_);
  return std::chrono::duration<double>(Clock::now() - last_activity_).count();
}

std::uint64_t Session::version() const {
  std::lock_guard lock(mutex_);
  return record_.version;
}

std::uint64_t Session::accepted_version() const {
  std::lock_guard lock(mutex_);
  return assigned_version_;
}

std::size_t Session::drivers() const {
  std::lock_guard lock(mutex_);
  return latest_pose_of_driver_.size();
}

}  // namespace filigree::server
