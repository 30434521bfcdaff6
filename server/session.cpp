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
  // One compute thread per session: sessions run side by side.
  d.threads = 1;
  return d;
}

void fill_stats(const FrameStats& s, double encode_ms, std::size_t bytes, v1::FrameStats& out) {
  out.set_cut_nodes(static_cast<std::uint32_t>(s.cut_nodes));
  out.set_regions(static_cast<std::uint32_t>(s.regions));
  out.set_largest_region(static_cast<std::uint32_t>(s.region_sizes.empty() ? 0 : s.region_sizes.front()));
  out.set_region_vertices(static_cast<std::uint32_t>(s.region_vertices));
  out.set_threshold(s.threshold);
  out.set_performance_estimate(s.performance_estimate);
  out.set_factorizations(static_cast<std::uint32_t>(s.factorizations));
  out.set_rotations_ms(s.rotations_ms);
  out.set_cut_update_ms(s.cut_update_ms);
  out.set_recover_ms(s.recover_ms);
  out.set_regions_ms(s.regions_ms);
  out.set_compute_ms(s.total_ms);
  out.set_encode_ms(encode_ms);
  out.set_encoded_bytes(static_cast<std::uint32_t>(bytes));
}

// Automatic quantization (SessionOptions.quantization_bits = 0) keeps every
// error within this fraction of the rest mesh's diagonal.
constexpr double kAutomaticError = 5e-5;

FrameEncoderOptions encoder_options(const v1::SessionOptions& o, const SessionAssets& assets) {
  FrameEncoderOptions e;
  e.chunk_vertices = assets.chunk_vertices;
  e.bits = o.quantization_bits();
  e.max_error = kAutomaticError * std::max(assets.rest_diagonal, 1e-30);
  e.staging = assets.staging;
  return e;
}

// The quantization of `values` with fixed bits, or with the fewest whose
// exact error against exact(i) stays within `target`; and that error.
template <class Exact>
std::pair<DeltaQuantization, double> quantize_within(std::span<const float> values, std::uint32_t fixed, double target,
                                                     const Exact& exact) {
  DeltaQuantization q = quantization_over(values, fixed ? fixed : 8);
  if (!fixed) q.bits = bits_for_error(q.range, target);
  // Decoded a block at a time: a buffer of every value (15 MB at 1.25M
  // vertices), freshly allocated, cost ~60 ms in page faults alone.
  constexpr std::size_t kBlock = 4096;
  std::array<float, kBlock> decoded;
  while (true) {
    double error = 0.0;
    for (std::size_t b = 0; b < values.size(); b += kBlock) {
      const std::size_t n = std::min(kBlock, values.size() - b);
      q.decode(values.subspan(b, n), std::span<float>(decoded.data(), n));
      for (std::size_t i = 0; i < n; ++i) error = std::max(error, std::abs(double{decoded[i]} - exact(b + i)));
    }
    if (fixed || error <= target || q.bits >= 24) return {q, error};
    ++q.bits;  // float rounding pushed past the target: one more bit
  }
}

// How many tasks encode a frame's chunks. A task's chunks run their entropy
// coders in one loop (encode_draco_many: 41% less time per vertex at 1.25M
// in the encoder bench), so fewer, larger tasks do less work: up to
// kDracoInterleave chunks each. A session alone on the machine also needs
// its tasks to balance over the threads: a multiple of them, of even sizes.
// Sharing it, other sessions' tasks fill the threads.
std::size_t encoding_parts(std::size_t chunks, std::size_t threads, bool alone) {
  const std::size_t fewest = (chunks + kDracoInterleave - 1) / kDracoInterleave;
  if (!alone || threads <= 1) return std::max<std::size_t>(fewest, 1);
  return std::clamp<std::size_t>((fewest + threads - 1) / threads * threads, 1, std::max<std::size_t>(chunks, 1));
}

}  // namespace

Session::Session(SessionRecord record, std::shared_ptr<const SessionAssets> assets, FrameScheduler& scheduler,
                 Journal journal)
    : assets_(std::move(assets)), scheduler_(scheduler), lane_(scheduler.lane()),
      encoder_(assets_->hierarchy().rest_positions, encoder_options(record.options, *assets_)),
      record_(std::move(record)), last_activity_(Clock::now()), journal_(std::move(journal)) {
  const Hierarchy& h = assets_->hierarchy();
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
  auto f = std::make_unique<InFlight>();
  f->single = true;
  if (!compute_frame(*f, /*keep_version=*/true)) return;
  f->force_keyframe = true;
  f->chunk_parts = encoding_parts(encoder_.chunk_count(), 1, false);
  f->encode_start = Clock::now();  // publish() reports the encode time from here
  encoder_.begin(true);
  for (std::size_t p = 0; p <= f->chunk_parts; ++p) {
    quantize_part_of(*f, p);
    encode_part_of(*f, p);
  }
  release_frame();
  publish(*f);
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
    seq = ++journal_seq_;
    if (journal_now) progress = progress_with_change_locked();
    pending_ = true;
    maybe_compute_locked();
    touch();
  }
  if (journal_now) journal(progress, seq);
}

void Session::submit_joints(const PoseOrigin& origin, const v1::JointPose& joints) {
  if (!rig_)
    throw PoseError("session " + record_.id + " has no skeleton (its upload was not a skinned glTF): pose it by positions");
  const bool model = joints.space() == v1::JointPose::SPACE_MODEL_MATRIX;
  if (!model && joints.space() != v1::JointPose::SPACE_LOCAL_TRS)
    throw PoseError("joint pose space " + std::to_string(joints.space()) + " is unknown");
  const std::size_t per = model ? 16 : 10, n = rig_->joints.size();
  const std::size_t count = joints.joint_indices().empty() ? n : static_cast<std::size_t>(joints.joint_indices_size());
  if (static_cast<std::size_t>(joints.values_size()) != per * count)
    throw PoseError("joint pose has " + std::to_string(joints.values_size()) + " values for " + std::to_string(count) +
                    " joints; expected " + std::to_string(per * count) + " (" + std::to_string(per) + " per joint)");
  std::vector<bool> seen(n, false);
  for (int i = 0; i < joints.joint_indices_size(); ++i) {
    const std::uint32_t j = joints.joint_indices(i);
    if (j >= n)
      throw PoseError("joint index " + std::to_string(j) + " at position " + std::to_string(i) +
                      " is out of range: the skeleton has " + std::to_string(n) + " joints");
    if (seen[j]) throw PoseError("joint " + std::to_string(j) + " is named twice in one pose");
    seen[j] = true;
  }
  for (int i = 0; i < joints.values_size(); ++i)
    if (!std::isfinite(joints.values(i))) {
      const std::size_t entry = static_cast<std::size_t>(i) / per;
      const std::size_t joint = joints.joint_indices().empty() ? entry : joints.joint_indices(static_cast<int>(entry));
      throw PoseError("joint pose value " + std::to_string(i) + " (joint " + std::to_string(joint) + ") is not finite (NaN or Inf)");
    }
  // Parse all joints before changing the state: a bad one changes nothing.
  std::vector<JointTransform> locals(model ? 0 : count);
  std::vector<Mat4> matrices(model ? count : 0);
  for (std::size_t k = 0; k < count; ++k) {
    const float* v = joints.values().data() + per * k;
    // Errors name the joint (its index in the skeleton), not the entry.
    const std::size_t joint = joints.joint_indices().empty() ? k : joints.joint_indices(static_cast<int>(k));
    if (model) {
      Mat4 m;
      for (int c = 0; c < 16; ++c) m(c % 4, c / 4) = v[c];  // column-major
      if (std::abs(m(3, 0)) > 1e-6 || std::abs(m(3, 1)) > 1e-6 || std::abs(m(3, 2)) > 1e-6 || std::abs(m(3, 3) - 1.0) > 1e-6)
        throw PoseError("joint " + std::to_string(joint) + "'s matrix is not affine (its last row must be 0 0 0 1)");
      matrices[k] = m;
    } else {
      JointTransform& t = locals[k];
      t.translation = Vec3(v[0], v[1], v[2]);
      const Eigen::Quaterniond q(v[6], v[3], v[4], v[5]);  // given x y z w
      if (!(q.norm() > 1e-6)) throw PoseError("joint " + std::to_string(joint) + " has a zero rotation quaternion");
      t.rotation = q.normalized();
      t.scale = Vec3(v[7], v[8], v[9]);
    }
  }
  std::lock_guard lock(skeleton_mutex_);
  const SkeletonPose before = *joint_pose_;
  for (std::size_t k = 0; k < count; ++k) {
    const std::size_t j = joints.joint_indices().empty() ? k : joints.joint_indices(static_cast<int>(k));
    if (model) {
      joint_pose_->model[j] = matrices[k];
    } else {
      joint_pose_->local[j] = locals[k];
      joint_pose_->model[j].reset();
    }
  }
  try {
    submit_skinned_locked(origin);
  } catch (const PoseError&) {
    *joint_pose_ = before;  // a refused pose changes nothing
    throw;
  }
}

const AnimationClip* Session::clip(const std::string& name) const { return rig_ ? rig_->clip(name) : nullptr; }

void Session::submit_clip_sample(const PoseOrigin& origin, const AnimationClip& clip, double seconds) {
  std::lock_guard lock(skeleton_mutex_);
  for (const ClipChannel& c : clip.channels) {
    joint_pose_->local[c.joint] = rig_->joints[c.joint].rest;
    joint_pose_->model[c.joint].reset();
  }
  sample_clip(clip, seconds, joint_pose_->local);
  submit_skinned_locked(origin);
}

void Session::submit_skinned_locked(const PoseOrigin& origin) {
  const std::size_t m = rig_->vertex_count();
  std::vector<Vec3>& skinned = skinned_positions_;  // reused pose to pose (skeleton_mutex_ held)
  skinned.resize(m);
  try {
    const std::vector<Mat4> model = model_transforms(*rig_, *joint_pose_);
    skin(*rig_, model,
         record_.options.skinning() == v1::SKINNING_DUAL_QUATERNION ? SkinningMethod::kDualQuaternion
                                                                    : SkinningMethod::kLinearBlend,
         skinned);
  } catch (const RigError& e) {
    throw PoseError(std::string("the joint pose cannot skin the base: ") + e.what());
  }
  skinned_.resize(3 * m);
  for (std::size_t i = 0; i < m; ++i)
    for (int k = 0; k < 3; ++k) {
      const double c = skinned[i][k];
      if (!std::isfinite(c)) throw PoseError("the joint pose moves base vertex " + std::to_string(i) + " to a non-finite place");
      check_reach(c, "the joint pose's base vertex", i);
      skinned_[3 * i + k] = static_cast<float>(c);
    }
  merge(origin, {}, skinned_, /*skinned=*/true);
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

std::shared_ptr<const PublishedFrame> Session::with_single(const std::shared_ptr<const PublishedFrame>& frame) {
  // Decode what clients of the chunked frame see, then encode it as one buffer.
  const std::size_t n = encoder_.vertex_count();
  KeyedDeltas decoded(n);
  const auto views_of = [](const v1::Frame& f) {
    std::vector<DeltaChunkView> views;
    for (const v1::DeltaChunk& c : f.chunks())
      views.push_back({c.first_vertex(), c.vertex_count(), {c.runs().data(), static_cast<std::size_t>(c.runs_size())}, c.deltas()});
    return views;
  };
  if (frame->keyframe) decoded.apply(frame->keyframe->frame.version(), frame->keyframe->frame.version(), views_of(frame->keyframe->frame));
  decoded.apply(frame->frame.version(), frame->frame.keyframe_version(), views_of(frame->frame));
  const std::span<const float> values = decoded.deltas();  // not copied: 15 MB at 1.25M, ~60 ms of page faults
  auto single = std::make_shared<v1::Frame>(frame->frame);
  single->clear_chunks();
  single->clear_keyframe_version();
  if (std::any_of(values.begin(), values.end(), [](float v) { return v != 0.0f; })) {
    const double target = kAutomaticError * std::max(assets_->rest_diagonal, 1e-30);
    // What is left of the target after the chunked frame's own error.
    const auto [q, error] = quantize_within(values, record_.options.quantization_bits(),
                                            std::max(target - frame->frame.max_error(), target / 4),
                                            [&](std::size_t i) { return double{values[i]}; });
    single->set_deltas(encode_draco(values, q));
    // Bounded, not exact: the chunked frame's error plus the requantization's.
    single->set_max_error(float_at_least(double{frame->frame.max_error()} + error));
    single->set_quantization_bits(q.bits);
    single->set_delta_min(q.min);
    single->set_delta_range(q.range);
  } else {
    single->clear_deltas();
    single->set_quantization_bits(0);
  }
  single->mutable_stats()->set_encoded_bytes(static_cast<std::uint32_t>(single->deltas().size()));
  single->mutable_stats()->set_present_vertices(static_cast<std::uint32_t>(n));
  auto out = std::make_shared<PublishedFrame>(*frame);
  out->single = std::move(single);
  std::lock_guard lock(mutex_);
  if (current_ == frame) current_ = out;  // later subscribers reuse it
  return out;
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

std::size_t Session::set_handles(const std::string& client_name, const std::vector<std::pair<Index, Vec3>>& handles) {
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
    for (auto it = handles_.begin(); it != handles_.end();) {
      std::erase_if(it->second, [&](const HandleEntry& e) { return e.client == client_name; });
      it = it->second.empty() ? handles_.erase(it) : std::next(it);
    }
    for (const auto& [v, target] : handles) handles_[v].push_back({target, client_name, ++handle_stamp_});
    count = handles_.size();
    v1::Change& change = changes_[client_name];
    change.set_client_name(client_name);
    change.set_vertex_count(change.vertex_count() + static_cast<std::uint32_t>(handles.size()));
    handles_dirty_ = true;
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

std::uint64_t Session::set_threshold(double threshold, bool whole_mesh) {
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
  {
    std::lock_guard lock(mutex_);
    closed_ = true;
    stopping_ = true;
    for (const auto& w : sinks_)
      if (auto s = w.lock()) sinks.push_back(s);
    sinks_.clear();
  }
  for (const auto& s : sinks) s->close(true, {});
}

bool Session::evict_if_unused() {
  std::lock_guard lock(mutex_);
  for (const auto& w : sinks_)
    if (!w.expired()) return false;
  evicted_ = closed_ = stopping_ = true;
  return true;
}

void Session::throw_evicted() const {
  throw StoreUnavailable("session " + record_.id + " left this server's memory while the request ran: retry");
}

void Session::close_streams(const std::string& why) {
  std::vector<std::shared_ptr<FrameSink>> sinks;
  {
    std::lock_guard lock(mutex_);
    for (const auto& w : sinks_)
      if (auto s = w.lock()) sinks.push_back(s);
    sinks_.clear();
  }
  for (const auto& s : sinks) s->close(false, why);
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

bool Session::want_single_locked() const {
  for (const auto& w : sinks_)
    if (const auto sink = w.lock(); sink && sink->format() == v1::FRAME_FORMAT_SINGLE) return true;
  return false;
}

void Session::maybe_compute_locked() {
  // frame_ is free once the encoding frame's parts have read it, and no
  // computed frame waits for the encoder.
  if (stopping_ || !pending_ || computing_ || computed_ || positions_busy_ > 0) return;
  computing_ = true;
  scheduler_.post(*lane_, [this] { compute_task(); });
}

void Session::release_frame() { assets_->frames->give(std::exchange(frame_, {})); }

void Session::compute_task() {
  auto f = std::make_unique<InFlight>();
  {
    std::lock_guard lock(mutex_);
    if (stopping_) {
      computing_ = false;
      return;
    }
    f->single = want_single_locked();
  }
  // Alone on the machine a session's compute uses every core; sharing it,
  // one (the other sessions keep the rest busy).
  deformer_->set_threads(scheduler_.busy_lanes() <= 1 ? static_cast<int>(scheduler_.threads()) : 1);
  const bool ok = compute_frame(*f, /*keep_version=*/false);
  std::lock_guard lock(mutex_);
  computing_ = false;
  if (ok && !stopping_) {
    computed_ = std::move(f);
    if (!encoding_) start_encode_locked();
  }
  maybe_compute_locked();
}

void Session::start_encode_locked() {
  encoding_ = std::move(computed_);
  InFlight* f = encoding_.get();
  f->force_keyframe = f->force_keyframe || std::exchange(keyframe_needed_, false) || !keyframe_;
  encoder_.begin(f->force_keyframe);
  f->encode_start = Clock::now();
  f->chunk_parts = encoding_parts(encoder_.chunk_count(), scheduler_.threads(), scheduler_.busy_lanes() <= 1);
  const std::size_t parts = f->chunk_parts + (f->single ? 1 : 0);
  positions_busy_ = parts_left_ = parts;
  for (std::size_t p = 0; p < parts; ++p) scheduler_.post(*lane_, [this, f, p] { part_task(f, p); });
}

std::pair<std::size_t, std::size_t> Session::chunks_of_part(const InFlight& f, std::size_t p) const {
  // The longer runs first: workers take parts in order, each the next when
  // done, so the short ones at the end even out the finish (alternating
  // sizes gave one worker every long run).
  const std::size_t n = encoder_.chunk_count(), size = n / f.chunk_parts, longer = n % f.chunk_parts;
  const std::size_t first = p * size + std::min(p, longer);
  return {first, first + size + (p < longer ? 1 : 0)};
}

void Session::quantize_part_of(InFlight& f, std::size_t p) {
  if (p < f.chunk_parts) {
    const auto [first, end] = chunks_of_part(f, p);
    for (std::size_t c = first; c < end; ++c) encoder_.quantize_chunk(c, frame_);
    return;
  }
  // The single buffer: every delta over one range (FRAME_FORMAT_SINGLE).
  const std::span<const Vec3> rest = assets_->hierarchy().rest_positions;
  f.single_values.resize(3 * rest.size());
  bool all_zero = true;
  for (std::size_t i = 0; i < rest.size(); ++i)
    for (int k = 0; k < 3; ++k) {
      const double d = frame_[i][k] - rest[i][k];
      if (!std::isfinite(d) || std::abs(d) > kMaxDeltaMagnitude)
        throw DeltaCodecError("delta of vertex " + std::to_string(i) + " is not finite or implausibly large");
      f.single_values[3 * i + k] = static_cast<float>(d);
      all_zero &= d == 0.0;
    }
  if (all_zero) {
    f.single_values.clear();
    f.single_quantization = {};
    f.single_error = 0.0;
    return;
  }
  const double target = kAutomaticError * std::max(assets_->rest_diagonal, 1e-30);
  std::tie(f.single_quantization, f.single_error) =
      quantize_within(f.single_values, record_.options.quantization_bits(), target,
                      [&](std::size_t i) { return frame_[i / 3][static_cast<int>(i % 3)] - rest[i / 3][static_cast<int>(i % 3)]; });
}

void Session::encode_part_of(InFlight& f, std::size_t p) {
  if (p < f.chunk_parts) {
    const auto [first, end] = chunks_of_part(f, p);
    return encoder_.encode_chunks(first, end - first);
  }
  f.single_bytes = encode_draco(f.single_values, f.single_quantization);
}

void Session::part_task(InFlight* f, std::size_t p) {
  try {
    quantize_part_of(*f, p);
  } catch (const std::exception& e) {
    if (!f->failed.exchange(true)) spdlog::error("session={} event=encode_failed error=\"{}\"", record_.id, e.what());
  }
  {
    std::lock_guard lock(mutex_);
    if (--positions_busy_ == 0) {
      release_frame();
      maybe_compute_locked();  // the next frame may compute now
    }
  }
  try {
    if (!f->failed) encode_part_of(*f, p);
  } catch (const std::exception& e) {
    if (!f->failed.exchange(true)) spdlog::error("session={} event=encode_failed error=\"{}\"", record_.id, e.what());
  }
  {
    std::lock_guard lock(mutex_);
    if (--parts_left_ > 0) return;
  }
  // The last part: publish, then start the frame that waited.
  if (!f->failed) {
    publish(*f);
  } else {
    encoder_.finish();
    std::lock_guard lock(mutex_);
    keyframe_needed_ = true;  // clients' state must not depend on a frame never sent
  }
  std::lock_guard lock(mutex_);
  encoding_.reset();
  if (computed_ && !stopping_) start_encode_locked();
  maybe_compute_locked();
}

bool Session::compute_frame(InFlight& f, bool keep_version) {
  const Hierarchy& h = assets_->hierarchy();
  const std::size_t m = h.base_vertices.size();
  // Buffers reused frame to frame; one compute at a time.
  Pose& pose = scratch_pose_;
  pose.positions.resize(m);
  std::optional<double> threshold;
  std::unique_ptr<Deformer> warm;  // set_threshold's, for T = ∞: dropped when this frame ends
  std::vector<HandleTarget> handle_targets;
  std::uint64_t seq;
  SessionProgress progress;
  {
    std::lock_guard lock(mutex_);
    pending_ = false;
    f.version = keep_version ? record_.version : ++assigned_version_;
    if (handles_dirty_) {
      handles_dirty_ = false;
      handles_solving_ = !handles_.empty();  // cleared where the solved pose is written back
      for (const auto& [v, entries] : handles_) {
        const auto newest = std::max_element(entries.begin(), entries.end(),
                                             [](const HandleEntry& a, const HandleEntry& b) { return a.stamp < b.stamp; });
        // The handle moves the vertex's MAPS point on the base by the same
        // displacement as the vertex (the point is not exactly at the vertex).
        const Vec3 maps_rest = h.maps_position(v, h.rest_positions);
        handle_targets.push_back({h.maps_face[v], h.maps_barycentric(v), newest->target - h.rest_positions[v] + maps_rest});
      }
    }
    for (std::size_t i = 0; i < m; ++i)
      pose.positions[i] = Vec3(record_.pose[3 * i], record_.pose[3 * i + 1], record_.pose[3 * i + 2]);
    f.pose_of_driver = latest_pose_of_driver_;
    f.force_keyframe = std::exchange(keyframe_requested_, false);
    f.changes.swap(changes_);
    touched_.clear();
    threshold.swap(pending_threshold_);
    if (threshold) warm.swap(warm_);  // released once this frame has applied the threshold
    seq = journal_seq_;
  }
  // A version (and keyframe request) given out but never published is taken
  // back (computes are serial, so no later one exists yet).
  const auto give_back = [&] {
    std::lock_guard lock(mutex_);
    if (!keep_version) --assigned_version_;
    keyframe_requested_ |= f.force_keyframe;  // still owed to the next frame
    if (std::exchange(handles_solving_, false)) handles_dirty_ = true;  // solved again next frame
  };
  try {
    if (!handle_targets.empty()) {
      // Handles move the whole base pose (as-rigid-as-possible from the current one).
      pose = handle_solver_->solve(handle_targets, pose);
      std::lock_guard lock(mutex_);
      handles_solving_ = false;
      if (journal_seq_ == seq) {
        for (std::size_t i = 0; i < m; ++i)
          for (int k = 0; k < 3; ++k) record_.pose[3 * i + k] = static_cast<float>(pose.positions[i][k]);
        seq = ++journal_seq_;
      } else {
        // A pose was merged while this solved: keep it (writing back would
        // lose it) and solve the handles again on top of it next frame.
        handles_dirty_ = true;
      }
    }
    if (journal_) {
      // Nothing is acknowledged (published) before it is journaled: the pose of this frame.
      progress.pose.resize(3 * m);
      for (std::size_t i = 0; i < m; ++i)
        for (int k = 0; k < 3; ++k) progress.pose[3 * i + k] = static_cast<float>(pose.positions[i][k]);
      std::lock_guard lock(mutex_);
      progress.options = record_.options;
      progress.version = f.version;
      progress.handles = handles_locked();
      progress.handles_pending = handles_pending_locked();
    }
    try {
      journal(progress, seq);
    } catch (const std::exception& e) {
      // Unjournaled frames must not be published: stop here; the registry
      // drops the session and the next call loads it from the store again.
      std::vector<std::shared_ptr<FrameSink>> sinks;
      {
        std::lock_guard lock(mutex_);
        failure_ = e.what();
        stopping_ = true;
        for (const auto& w : sinks_)
          if (auto sink = w.lock()) sinks.push_back(sink);
        sinks_.clear();
      }
      give_back();
      spdlog::warn("session={} event=journal_failed error=\"{}\"", record_.id, e.what());
      for (const auto& sink : sinks) sink->close(false, std::string("the session stopped on this replica: ") + e.what());
      return false;
    }
    // Held through the overlays: record() reads the cut this frame leaves.
    std::lock_guard cut_lock(cut_mutex_);
    if (threshold) deformer_->set_threshold(*threshold);
    // The rest pose gives the rest mesh exactly (no 1e-16 noise to encode).
    bool at_rest = true;
    for (std::size_t i = 0; i < m && at_rest; ++i)
      for (int k = 0; k < 3; ++k) at_rest &= static_cast<float>(pose.positions[i][k]) == assets_->base.positions(static_cast<int>(3 * i + k));
    // Deform anyway so the cut, regions and stats (overlays) follow this
    // frame; the deformer writes straight into the frame buffer.
    if (frame_.empty()) frame_ = assets_->frames->take(h.vertex_count());
    f.stats = deformer_->deform(pose, frame_);
    if (at_rest) std::copy(h.rest_positions.begin(), h.rest_positions.end(), frame_.begin());

    // Overlays only while a viewer asks for them: they are O(n) per frame.
    bool want_overlays;
    {
      std::lock_guard lock(mutex_);
      want_overlays = Clock::now() < overlays_wanted_until_;
    }
    if (want_overlays) {
      f.overlays = std::make_shared<v1::Overlays>();
      v1::Overlays& overlays = *f.overlays;
      overlays.set_ready(true);
      const std::vector<Index>& region = deformer_->region_of_vertex();
      std::uint32_t regions = 0;
      for (Index r : region) {
        overlays.add_region_of(r == kNone ? 0 : r + 1);
        if (r != kNone) regions = std::max<std::uint32_t>(regions, r + 1);
      }
      if (region.empty()) overlays.mutable_region_of()->Resize(static_cast<int>(h.vertex_count()), 0);
      overlays.set_region_count(regions);
      const CutState& cut = deformer_->cut_state();
      h.for_each_face([&](FaceId face, const Triangle& t) {
        if (cut.face_alive(face))
          for (Index v : t) overlays.add_cut_faces(v);
      });
    }
    return true;
  } catch (const std::exception& e) {
    give_back();
    release_frame();  // no part reads it: none runs during a compute
    // A compute failure must not take the server down; the session keeps
    // its last frame and logs why.
    spdlog::error("session={} event=compute_failed error=\"{}\"", record_.id, e.what());
    return false;
  }
}

void Session::publish(InFlight& f) {
  const EncodedFrameSummary summary = encoder_.finish();
  const double encode_ms = std::chrono::duration<double, std::milli>(Clock::now() - f.encode_start).count();
  auto published = std::make_shared<PublishedFrame>();
  published->pose_of_driver = std::move(f.pose_of_driver);
  published->wire_pool = assets_->wire;

  // What both formats share.
  v1::Frame common;
  common.set_version(f.version);
  common.set_vertex_count(static_cast<std::uint32_t>(encoder_.vertex_count()));
  for (auto& [name, change] : f.changes) *common.add_changes() = change;
  if (f.single) {
    auto single = std::make_shared<v1::Frame>(common);
    single->set_deltas(std::move(f.single_bytes));
    single->set_quantization_bits(f.single_quantization.bits);
    single->set_delta_min(f.single_quantization.min);
    single->set_delta_range(f.single_quantization.range);
    single->set_max_error(float_at_least(f.single_error));
    fill_stats(f.stats, encode_ms, single->deltas().size(), *single->mutable_stats());
    single->mutable_stats()->set_present_vertices(single->vertex_count());
    published->single = std::move(single);
  }
  v1::Frame& out = published->frame;
  out = std::move(common);
  std::uint32_t bits = 0;
  for (std::size_t c = 0; c < encoder_.chunk_count(); ++c) {
    EncodedChunk& chunk = encoder_.chunk(c);
    if (chunk.kind == EncodedChunk::Kind::kAbsent) continue;
    v1::DeltaChunk& d = *out.add_chunks();
    d.set_first_vertex(chunk.first);
    d.set_vertex_count(chunk.count);
    d.mutable_runs()->Add(chunk.runs.begin(), chunk.runs.end());
    d.set_deltas(std::move(chunk.bytes));
    d.set_quantization_bits(chunk.quantization.bits);
    d.set_delta_min(chunk.quantization.min);
    d.set_delta_range(chunk.quantization.range);
    bits = std::max(bits, chunk.quantization.bits);
  }
  out.set_quantization_bits(bits);
  out.set_max_error(float_at_least(summary.max_error));
  fill_stats(f.stats, encode_ms, summary.bytes, *out.mutable_stats());
  out.mutable_stats()->set_present_vertices(static_cast<std::uint32_t>(summary.present_vertices));

  {
    std::lock_guard lock(mutex_);
    if (summary.keyframe || !keyframe_) {
      out.set_keyframe_version(f.version);
    } else {
      out.set_keyframe_version(keyframe_->frame.version());
      published->keyframe = keyframe_;
    }
  }
  // A single-buffer subscriber came while this frame computed without it.
  bool single_wanted;
  {
    std::lock_guard lock(mutex_);
    single_wanted = !published->single && want_single_locked();
  }
  std::shared_ptr<const PublishedFrame> shared = published;
  if (single_wanted) {
    try {
      shared = with_single(shared);
    } catch (const std::exception& e) {
      spdlog::error("session={} event=transcode_failed error=\"{}\"", record_.id, e.what());
    }
  }
  std::vector<std::shared_ptr<FrameSink>> sinks;
  {
    std::lock_guard lock(mutex_);
    record_.version = f.version;
    if (f.overlays) f.overlays->set_version(record_.version);
    // Only the current frame's overlays are answered: a frame without them
    // lets the previous ones (megabytes at 1.25M vertices) go.
    overlays_ = f.overlays ? std::make_shared<const SerializedOnce>(std::move(f.overlays)) : nullptr;
    current_ = shared;
    if (!shared->keyframe) keyframe_ = shared;
    touch();
    std::erase_if(sinks_, [](const std::weak_ptr<FrameSink>& w) { return w.expired(); });
    for (const auto& w : sinks_)
      if (auto s = w.lock()) sinks.push_back(s);
  }
  // A stream starts its write inside offer(), and at 1.25M vertices that
  // write (~1 MB into the socket; the first also serializes the frame) takes
  // milliseconds: the drivers whose poses the frame answers go first, since
  // they wait for it (closed loop); watchers only follow. (A watcher first
  // held a driver's frame back by 3.0 ms at the median.)
  // (std::partition: stable_partition may allocate a buffer every frame.)
  std::partition(sinks.begin(), sinks.end(),
                 [&](const std::shared_ptr<FrameSink>& s) { return shared->pose_of_driver.contains(s->driver()); });
  for (const auto& s : sinks) s->offer(shared);
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

v1::SessionInfo Session::info() const {
  // The meshes are immutable: built and copied outside the session's lock.
  v1::SessionInfo info = own_info();
  *info.mutable_base() = assets_->base;
  *info.mutable_rest() = rest_mesh_message(assets_->hierarchy());
  info.mutable_rest()->mutable_uploaded_ids()->Add(record_.uploaded_ids.begin(), record_.uploaded_ids.end());
  return info;
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

grpc::ByteBuffer Session::info_wire(std::optional<std::uint64_t> version) const {
  v1::SessionInfo own = own_info();
  if (version) own.set_version(*version);
  // The ids never change after the session is made (record_.uploaded_ids is written only then).
  std::call_once(ids_wire_once_, [this] { ids_wire_ = uploaded_ids_field(record_.uploaded_ids); });
  return session_info_wire(own, *assets_->info_wire, ids_wire_);
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
