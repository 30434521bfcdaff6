#include "server/session.h"

#include <chrono>
#include <cmath>
#include <limits>

#include <spdlog/spdlog.h>

#include "codec/delta_codec.h"
#include "hierarchy/cut_state.h"
#include "runtime/deformer.h"
#include "runtime/handle_solver.h"
#include "runtime/pose.h"

namespace filigree::server {
namespace {

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

// The fewest bits (8…24) whose half quantization step over the deltas' range
// stays within kAutomaticError of the diagonal (Frame.quantization_bits).
constexpr double kAutomaticError = 5e-5;
std::uint32_t automatic_bits(const std::vector<Vec3>& deltas, double diagonal) {
  double lo = 0.0, hi = 0.0;
  for (const Vec3& d : deltas) lo = std::min(lo, d.minCoeff()), hi = std::max(hi, d.maxCoeff());
  const double steps = (hi - lo) / (2.0 * kAutomaticError * std::max(diagonal, 1e-300));
  std::uint32_t bits = 8;
  while (bits < 24 && static_cast<double>((1u << bits) - 1) < steps) ++bits;
  return bits;
}

}  // namespace

Session::Session(SessionRecord record, std::shared_ptr<const SessionAssets> assets, Journal journal)
    : assets_(std::move(assets)), record_(std::move(record)), last_activity_(Clock::now()), journal_(std::move(journal)) {
  const Hierarchy& h = assets_->hierarchy();
  const v1::BaseMesh& base = assets_->base;
  if (record_.pose.size() != 3 * h.base_vertices.size()) record_.pose.assign(base.positions().begin(), base.positions().end());

  deformer_ = std::make_unique<Deformer>(assets_->model, deformer_options(record_.options));
  handle_solver_ = std::make_unique<HandleSolver>(h.base_mesh());
  // The current frame exists from the start: the rest mesh, or after a
  // restart the latest pose, under the version it had.
  compute_once(true);
  worker_ = std::thread([this] { run(); });
}

Session::~Session() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  wake_.notify_all();
  if (worker_.joinable()) worker_.join();
}

Role Session::authorize(const std::string& token) const {
  if (token.empty()) return Role::kNone;
  if (token == record_.editor_token) return Role::kEditor;
  if (token == record_.viewer_token) return Role::kViewer;
  return Role::kNone;
}

void Session::touch() { last_activity_ = Clock::now(); }

void Session::submit(std::uint64_t driver, const std::string& client_name, std::uint64_t pose_id,
                     std::span<const std::uint32_t> indices, std::span<const float> positions) {
  const std::size_t m = assets_->hierarchy().base_vertices.size();
  const std::size_t count = indices.empty() ? m : indices.size();
  if (positions.size() != 3 * count)
    throw PoseError("pose has " + std::to_string(positions.size()) + " coordinates for " + std::to_string(count) +
                    (indices.empty() ? " base vertices (a full pose)" : " indices") + "; expected " + std::to_string(3 * count));
  for (std::size_t i = 0; i < indices.size(); ++i)
    if (indices[i] >= m)
      throw PoseError("pose index " + std::to_string(indices[i]) + " at position " + std::to_string(i) +
                      " is out of range: the base mesh has " + std::to_string(m) + " vertices");
  for (std::size_t i = 0; i < positions.size(); ++i)
    if (!std::isfinite(positions[i])) throw PoseError("pose coordinate " + std::to_string(i) + " is not finite (NaN or Inf)");

  std::uint64_t seq;
  SessionProgress progress;
  {
    std::lock_guard lock(mutex_);
    if (closed_) return;
    for (std::size_t i = 0; i < count; ++i) {
      const std::size_t v = indices.empty() ? i : indices[i];
      for (int k = 0; k < 3; ++k) record_.pose[3 * v + k] = positions[3 * i + k];
    }
    if (driver != 0) latest_pose_of_driver_[driver] = pose_id;  // 0: a unary pose, no stream to answer
    v1::Change& change = changes_[client_name];
    change.set_client_name(client_name);
    change.set_pose_id(pose_id);
    change.set_vertex_count(change.vertex_count() + static_cast<std::uint32_t>(count));
    pending_ = true;
    seq = ++journal_seq_;
    if (journal_) progress = progress_with_change_locked();
    touch();
  }
  wake_.notify_one();
  journal(progress, seq);
}

void Session::subscribe(const std::shared_ptr<FrameSink>& sink, std::optional<std::uint64_t> after_version) {
  std::shared_ptr<const PublishedFrame> now;
  {
    std::lock_guard lock(mutex_);
    if (closed_) {
      sink->close(true, {});
      return;
    }
    sinks_.push_back(sink);
    if (current_ && (!after_version || current_->frame.version() > *after_version)) now = current_;
    touch();
  }
  if (now) sink->offer(now);
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
  }
  std::size_t count = 0;
  {
    std::lock_guard lock(mutex_);
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
    pending_ = true;
    touch();
  }
  wake_.notify_one();
  return count;
}

void Session::set_threshold(double threshold, bool whole_mesh) {
  std::uint64_t seq;
  SessionProgress progress;
  {
    std::lock_guard lock(mutex_);
    record_.options.set_threshold(threshold);
    record_.options.set_whole_mesh(whole_mesh);
    pending_threshold_ = whole_mesh ? DeformerOptions::kInfinity : threshold;
    pending_ = true;
    seq = ++journal_seq_;
    if (journal_) progress = progress_with_change_locked();
    touch();
  }
  wake_.notify_one();
  journal(progress, seq);
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
  wake_.notify_all();
  for (const auto& s : sinks) s->close(true, {});
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
  return {record_.options, record_.pose, record_.version + 1 + (computing_ ? 1 : 0)};
}

void Session::journal(const SessionProgress& progress, std::uint64_t seq) {
  if (!journal_) return;
  std::lock_guard lock(journal_mutex_);
  if (seq <= journaled_seq_) return;  // a later snapshot, with this change, is stored
  journal_(progress);
  journaled_seq_ = seq;
}

void Session::run() {
  while (true) {
    {
      std::unique_lock lock(mutex_);
      wake_.wait(lock, [&] { return pending_ || stopping_; });
      if (stopping_) return;
    }
    compute_once(false);
  }
}

void Session::compute_once(bool keep_version) {
  const Hierarchy& h = assets_->hierarchy();
  const std::size_t m = h.base_vertices.size();
  // Buffers reused frame to frame; only this session's worker computes.
  Pose& pose = scratch_pose_;
  pose.positions.resize(m);
  std::unordered_map<std::uint64_t, std::uint64_t> pose_of_driver;
  std::map<std::string, v1::Change> changes;
  std::optional<double> threshold;
  std::uint32_t bits;
  std::vector<HandleTarget> handle_targets;
  std::uint64_t seq;
  SessionProgress progress;
  {
    std::lock_guard lock(mutex_);
    pending_ = false;
    computing_ = true;
    if (handles_dirty_) {
      handles_dirty_ = false;
      for (const auto& [v, entries] : handles_) {
        const auto newest = std::max_element(entries.begin(), entries.end(),
                                             [](const HandleEntry& a, const HandleEntry& b) { return a.stamp < b.stamp; });
        // The handle moves the vertex's MAPS point on the base by the same
        // displacement as the vertex (the point is not exactly at the vertex).
        const Vec3 maps_rest = h.maps_position(v, h.rest_positions);
        handle_targets.push_back({h.maps_face[v], h.maps_bary[v].cast<double>(), newest->target - h.rest_positions[v] + maps_rest});
      }
    }
    for (std::size_t i = 0; i < m; ++i)
      pose.positions[i] = Vec3(record_.pose[3 * i], record_.pose[3 * i + 1], record_.pose[3 * i + 2]);
    pose_of_driver = latest_pose_of_driver_;
    changes.swap(changes_);
    threshold.swap(pending_threshold_);
    bits = record_.options.quantization_bits();
    seq = journal_seq_;
  }
  try {
    if (!handle_targets.empty()) {
      // Handles move the whole base pose (as-rigid-as-possible from the current one).
      pose = handle_solver_->solve(handle_targets, pose);
      std::lock_guard lock(mutex_);
      for (std::size_t i = 0; i < m; ++i)
        for (int k = 0; k < 3; ++k) record_.pose[3 * i + k] = static_cast<float>(pose.positions[i][k]);
      seq = ++journal_seq_;
    }
    if (journal_) {
      // Nothing is acknowledged (published) before it is journaled: the pose of this frame.
      progress.pose.resize(3 * m);
      for (std::size_t i = 0; i < m; ++i)
        for (int k = 0; k < 3; ++k) progress.pose[3 * i + k] = static_cast<float>(pose.positions[i][k]);
      std::lock_guard lock(mutex_);
      progress.options = record_.options;
      progress.version = keep_version ? record_.version : record_.version + 1;
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
        computing_ = false;
        for (const auto& w : sinks_)
          if (auto sink = w.lock()) sinks.push_back(sink);
        sinks_.clear();
      }
      spdlog::warn("session={} event=journal_failed error=\"{}\"", record_.id, e.what());
      for (const auto& sink : sinks) sink->close(false, std::string("the session stopped on this replica: ") + e.what());
      return;
    }
    if (threshold) deformer_->set_threshold(*threshold);
    // The rest pose gives the rest mesh exactly (no 1e-16 noise to encode).
    bool at_rest = true;
    for (std::size_t i = 0; i < m && at_rest; ++i)
      for (int k = 0; k < 3; ++k) at_rest &= static_cast<float>(pose.positions[i][k]) == assets_->base.positions(static_cast<int>(3 * i + k));
    // Deform anyway so the cut, regions and stats (overlays) follow this
    // frame; the deformer writes straight into the frame buffer, which then
    // becomes the deltas in place.
    std::vector<Vec3>& deltas = frame_;
    deltas.resize(h.vertex_count());
    const FrameStats stats = deformer_->deform(pose, deltas);
    const auto t = Clock::now();
    if (at_rest) {
      std::fill(deltas.begin(), deltas.end(), Vec3::Zero());
    } else {
      for (std::size_t i = 0; i < deltas.size(); ++i) deltas[i] -= h.rest_positions[i];
    }
    const EncodedDeltas enc = encode_deltas(deltas, bits ? bits : automatic_bits(deltas, assets_->rest_diagonal));
    const double encode_ms = std::chrono::duration<double, std::milli>(Clock::now() - t).count();

    auto published = std::make_shared<PublishedFrame>();
    v1::Frame& f = published->frame;
    f.set_deltas(enc.bytes);
    f.set_vertex_count(enc.count);
    f.set_quantization_bits(enc.bits);
    f.set_delta_min(enc.min);
    f.set_delta_range(enc.range);
    f.set_max_error(enc.max_error);
    for (auto& [name, change] : changes) *f.add_changes() = change;
    fill_stats(stats, encode_ms, enc.bytes.size(), *f.mutable_stats());
    published->pose_of_driver = std::move(pose_of_driver);

    // Overlays only while a viewer asks for them: they are O(n) per frame.
    std::shared_ptr<v1::Overlays> overlays;
    bool want_overlays;
    {
      std::lock_guard lock(mutex_);
      want_overlays = Clock::now() < overlays_wanted_until_;
    }
    if (want_overlays) {
      overlays = std::make_shared<v1::Overlays>();
      overlays->set_ready(true);
      const std::vector<Index>& region = deformer_->region_of_vertex();
      std::uint32_t regions = 0;
      for (Index r : region) {
        overlays->add_region_of(r == kNone ? 0 : r + 1);
        if (r != kNone) regions = std::max<std::uint32_t>(regions, r + 1);
      }
      if (region.empty()) overlays->mutable_region_of()->Resize(static_cast<int>(h.vertex_count()), 0);
      overlays->set_region_count(regions);
      const CutState& cut = deformer_->cut_state();
      for (FaceId f = 0; f < h.faces.size(); ++f)
        if (cut.face_alive(f))
          for (Index v : h.faces[f]) overlays->add_cut_faces(v);
    }

    std::vector<std::shared_ptr<FrameSink>> sinks;
    {
      std::lock_guard lock(mutex_);
      if (!keep_version) ++record_.version;
      computing_ = false;
      if (overlays) {
        overlays->set_version(record_.version);
        overlays_ = overlays;
      }
      f.set_version(record_.version);
      current_ = published;
      touch();
      std::erase_if(sinks_, [](const std::weak_ptr<FrameSink>& w) { return w.expired(); });
      for (const auto& w : sinks_)
        if (auto s = w.lock()) sinks.push_back(s);
    }
    for (const auto& s : sinks) s->offer(published);
  } catch (const std::exception& e) {
    {
      std::lock_guard lock(mutex_);
      computing_ = false;
    }
    // A compute failure must not take the server down; the session keeps
    // its last frame and logs why.
    spdlog::error("session={} event=compute_failed error=\"{}\"", record_.id, e.what());
  }
}

v1::Overlays Session::overlays() {
  bool had_recent;
  v1::Overlays out;
  {
    std::lock_guard lock(mutex_);
    had_recent = overlays_ && overlays_->version() == record_.version;
    overlays_wanted_until_ = Clock::now() + std::chrono::seconds(5);
    if (had_recent) {
      out = *overlays_;
    } else {
      pending_ = true;  // recompute the current pose once, with overlays
    }
    touch();
  }
  if (!had_recent) wake_.notify_one();
  return out;  // ready == false until a frame with overlays exists
}

v1::SessionInfo Session::info() const {
  v1::SessionInfo info;
  std::lock_guard lock(mutex_);
  info.set_session_id(record_.id);
  info.set_mesh_hash(record_.hierarchy_key.substr(0, 16));
  *info.mutable_base() = assets_->base;
  *info.mutable_rest() = assets_->rest;
  info.mutable_rest()->mutable_uploaded_ids()->Add(record_.uploaded_ids.begin(), record_.uploaded_ids.end());
  *info.mutable_options() = record_.options;
  info.set_version(record_.version);
  return info;
}

v1::SessionState Session::state() const {
  v1::SessionState s;
  std::lock_guard lock(mutex_);
  s.set_version(record_.version);
  for (float c : record_.pose) s.add_pose(c);
  if (current_) *s.mutable_frame() = current_->frame;
  return s;
}

SessionRecord Session::record() const {
  std::lock_guard lock(mutex_);
  return record_;
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
  return record_.version + (computing_ ? 1 : 0);
}

std::size_t Session::drivers() const {
  std::lock_guard lock(mutex_);
  return latest_pose_of_driver_.size();
}

}  // namespace filigree::server
