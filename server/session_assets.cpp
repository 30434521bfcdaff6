#include "server/session_assets.h"

#include <algorithm>

#include "codec/frame_encoder.h"
#include "hierarchy/hierarchy.h"
#include "runtime/deformer_model.h"
#include "server/level_geometry.h"
#include "server/session_info_wire.h"

namespace filigree::server {
namespace {

// The largest error automatic quantization allows, per unit of the rest mesh's diagonal.
constexpr double kAutomaticError = 5e-5;

// Vertices per frame chunk: 16384, or for a mesh of fewer than 2·threads
// such chunks, an even split into 2·threads of them (at least 2048 each), so
// that a small mesh's frame still encodes on every thread, two coders
// interleaved per task. Chunks of 4096 cost no more bytes than 16384 on the
// 26k Armadillo (1.480 against 1.492 B/vertex, encoder bench), and 20% more
// time per vertex on one thread.
std::uint32_t chunk_vertices_for(std::size_t vertices, std::size_t threads) {
  constexpr std::size_t kLargest = 16384, kSmallest = 2048;
  const std::size_t chunks = 2 * std::max<std::size_t>(threads, 1);
  return static_cast<std::uint32_t>(std::clamp((vertices + chunks - 1) / chunks, kSmallest, kLargest));
}

std::shared_ptr<const SessionAssets> make_assets(const std::shared_ptr<const Hierarchy>& hierarchy, std::size_t threads) {
  auto a = std::make_shared<SessionAssets>();
  a->model = DeformerModel::create(hierarchy);
  const Hierarchy& h = *hierarchy;
  const TriMesh base = h.base_mesh();
  for (const Vec3& p : base.positions)
    for (int k = 0; k < 3; ++k) a->base.add_positions(static_cast<float>(p[k]));
  for (const Triangle& f : base.faces)
    for (Index v : f) a->base.add_faces(v);
  for (Index v : h.base_vertices) a->base.add_original_ids(v);
  a->info_wire = std::make_shared<const MeshWire>(a->base, rest_mesh_message(h));
  a->rest_diagonal = bounding_box_diagonal(h.rest_positions);
  a->automatic_max_error = kAutomaticError * std::max(a->rest_diagonal, 1e-30);
  double farthest = 0.0;
  for (const Vec3& p : h.rest_positions) farthest = std::max(farthest, p.cwiseAbs().maxCoeff());
  a->pose_reach = farthest + kPoseReachSizes * std::max(a->rest_diagonal, 1e-30);
  // Frames: a few in flight at once. Staging: two frames' chunks, enough for
  // one encoding while the next frame quantizes.
  a->frames = std::make_shared<BufferPool<Vec3>>(4);
  a->chunk_vertices = chunk_vertices_for(h.vertex_count(), threads);
  const std::size_t chunks = FrameEncoder::chunk_count(h.vertex_count(), a->chunk_vertices);
  a->staging = std::make_shared<BufferPool<float>>(2 * chunks + 2);
  a->wire = std::make_shared<BufferPool<char>>(2);
  a->levels = std::make_shared<LevelGeometries>(*a->model);
  return a;
}

}  // namespace

FrameEncoderOptions frame_encoder_options(const v1::SessionOptions& o, const SessionAssets& assets) {
  FrameEncoderOptions e;
  e.chunk_vertices = assets.chunk_vertices;
  e.bits = o.quantization_bits();
  e.max_error = assets.automatic_max_error;
  e.staging = assets.staging;
  return e;
}

v1::RestMesh rest_mesh_message(const Hierarchy& h) {
  v1::RestMesh rest;
  rest.set_vertex_count(static_cast<std::uint32_t>(h.vertex_count()));
  rest.mutable_positions()->Reserve(static_cast<int>(3 * h.vertex_count()));
  for (const Vec3& p : h.rest_positions)
    for (int k = 0; k < 3; ++k) rest.add_positions(static_cast<float>(p[k]));
  rest.mutable_faces()->Reserve(static_cast<int>(3 * h.original_face_count()));
  for (const Triangle& f : h.original_faces)
    for (Index v : f) rest.add_faces(v);
  return rest;
}

const Hierarchy& SessionAssets::hierarchy() const { return model->hierarchy(); }

std::shared_ptr<const SessionAssets> SessionAssetsCache::get(const std::shared_ptr<const Hierarchy>& h, std::size_t threads) {
  std::lock_guard lock(mutex_);
  std::erase_if(assets_, [](const auto& entry) { return entry.second.expired(); });
  if (auto it = assets_.find(h.get()); it != assets_.end())
    if (auto live = it->second.lock()) return live;
  // Built under the lock: a second session of a mesh being set up waits for
  // the first instead of building a copy (building is O(n), well under the
  // preprocessing that precedes it).
  auto made = make_assets(h, threads);
  assets_[h.get()] = made;
  return made;
}

std::size_t SessionAssetsCache::trim_idle_pools() {
  std::vector<std::shared_ptr<const SessionAssets>> live;
  {
    std::lock_guard lock(mutex_);
    for (const auto& [h, weak] : assets_)
      if (auto a = weak.lock()) live.push_back(std::move(a));
  }
  std::size_t freed = 0;
  for (const auto& a : live)
    freed += a->frames->trim_if_idle() + a->staging->trim_if_idle() + a->wire->trim_if_idle() + a->model->recovery_scratch().trim_if_idle();
  return freed;
}

std::size_t SessionAssetsCache::live() const {
  std::lock_guard lock(mutex_);
  std::size_t n = 0;
  for (const auto& [h, weak] : assets_) n += weak.expired() ? 0 : 1;
  return n;
}

}  // namespace filigree::server
