#include "server/session.h"
// Session's frame pipeline (DESIGN §3): the compute on the session's lane,
// the quantizing and encoding of its chunks in parallel parts, the
// publication to every subscriber.

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <span>
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

namespace filigree::server {
namespace {

using Clock = std::chrono::steady_clock;

void fill_stats(const FrameStats& s, double encode_ms, std::size_t bytes, v1::FrameStats& out) {
  out.set_cut_nodes(static_cast<std::uint32_t>(s.cut_nodes));
  out.set_regions(static_cast<std::uint32_t>(s.regions));
  out.set_largest_region(static_cast<std::uint32_t>(s.region_sizes.empty() ? 0 : s.region_sizes.front()));
  out.set_region_vertices(static_cast<std::uint32_t>(s.region_vertices));
  out.set_threshold(s.threshold);
  out.set_cut_converged(s.cut_converged);
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

void Session::encode_first_frame() {
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
    const double target = assets_->automatic_max_error;
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
  std::vector<std::uint32_t> levels;
  {
    std::lock_guard lock(mutex_);
    if (stopping_) {
      computing_ = false;
      return;
    }
    f->single = want_single_locked();
    levels = wanted_levels_locked();
  }
  // Levels whose mesh is being built join the frame after it is
  // (compute_if_level_missing_locked).
  for (std::uint32_t level : levels)
    if (auto geometry = assets_->levels->find(level)) f->levels.push_back(std::move(geometry));
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
  const std::size_t parts = f->chunk_parts + (f->single ? 1 : 0) + (f->levels.empty() ? 0 : 1);
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

Session::PartKind Session::part_kind(const InFlight& f, std::size_t p) {
  if (p < f.chunk_parts) return PartKind::kChunks;
  return p == f.chunk_parts && f.single ? PartKind::kSingle : PartKind::kLevels;
}

void Session::quantize_part_of(InFlight& f, std::size_t p) {
  if (part_kind(f, p) == PartKind::kChunks) {
    const auto [first, end] = chunks_of_part(f, p);
    for (std::size_t c = first; c < end; ++c) encoder_.quantize_chunk(c, frame_);
    return;
  }
  if (part_kind(f, p) == PartKind::kLevels) {
    // Every level from the same positions as the full frame; one that fails
    // is left out of this frame (its next is a keyframe), the others go on.
    for (const auto& geometry : f.levels) {
      std::unique_ptr<LevelFrames>& level = level_frames_[geometry->vertex_count];
      try {
        if (!level) level = std::make_unique<LevelFrames>(geometry, frame_encoder_options(record_.options, *assets_));
        level->quantize(frame_, f.force_keyframe);
      } catch (const std::exception& e) {
        spdlog::error("session={} event=level_encode_failed level={} error=\"{}\"", record_.id, geometry->vertex_count, e.what());
        if (level) level->discard();
        f.levels_failed.push_back(geometry->vertex_count);
      }
    }
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
  const double target = assets_->automatic_max_error;
  std::tie(f.single_quantization, f.single_error) =
      quantize_within(f.single_values, record_.options.quantization_bits(), target,
                      [&](std::size_t i) { return frame_[i / 3][static_cast<int>(i % 3)] - rest[i / 3][static_cast<int>(i % 3)]; });
}

void Session::encode_part_of(InFlight& f, std::size_t p) {
  if (part_kind(f, p) == PartKind::kChunks) {
    const auto [first, end] = chunks_of_part(f, p);
    return encoder_.encode_chunks(first, end - first);
  }
  if (part_kind(f, p) == PartKind::kLevels) {
    for (const auto& geometry : f.levels) {
      const std::uint32_t vertices = geometry->vertex_count;
      if (std::find(f.levels_failed.begin(), f.levels_failed.end(), vertices) != f.levels_failed.end()) continue;
      LevelFrames& level = *level_frames_.at(vertices);
      try {
        level.encode();
      } catch (const std::exception& e) {
        spdlog::error("session={} event=level_encode_failed level={} error=\"{}\"", record_.id, vertices, e.what());
        level.discard();
        f.levels_failed.push_back(vertices);
      }
    }
    return;
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
    for (auto& [vertices, level] : level_frames_) level->discard();
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
        std::vector<float> solved(3 * m);
        for (std::size_t i = 0; i < m; ++i)
          for (int k = 0; k < 3; ++k) solved[3 * i + k] = static_cast<float>(pose.positions[i][k]);
        // The solved pose is the change of whoever set handles last.
        history_.record_pose(handles_origin_, v1::HistoryEntry::KIND_HANDLES, {}, record_.pose, solved);
        record_.pose = std::move(solved);
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
  // Each level of detail's frame: the same version and changes, the core's
  // stats, the level's own chunks.
  v1::FrameStats core_stats;
  fill_stats(f.stats, encode_ms, summary.bytes, core_stats);
  std::map<std::uint32_t, std::uint64_t> encoded;
  for (const auto& geometry : f.levels) {
    const std::uint32_t vertices = geometry->vertex_count;
    if (std::find(f.levels_failed.begin(), f.levels_failed.end(), vertices) != f.levels_failed.end()) continue;
    LevelFrames& level = *level_frames_.at(vertices);
    published->levels.emplace_back(vertices, level.publish(common, core_stats, published->pose_of_driver, assets_->wire));
    encoded[vertices] = level.frames_encoded();
  }
  // Encoders no stream wanted for this frame go.
  std::erase_if(level_frames_, [&](const auto& entry) {
    return std::none_of(f.levels.begin(), f.levels.end(), [&](const auto& g) { return g->vertex_count == entry.first; });
  });
  out = std::move(common);
  out.set_quantization_bits(move_chunks(encoder_, out));
  out.set_max_error(float_at_least(summary.max_error));
  *out.mutable_stats() = core_stats;
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
    level_frames_encoded_ = std::move(encoded);
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

}  // namespace filigree::server
