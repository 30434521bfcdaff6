#pragma once
// What every session of one mesh shares (DESIGN §3.1): the deformer model
// (hierarchy, traversal layout, lazily the Laplacian) and the base and rest
// meshes as clients receive them. Built once per hierarchy, read-only, and
// freed when the last session holding it goes.

#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>

#include "codec/frame_encoder.h"
#include "filigree/v1/filigree.pb.h"
#include "mesh/tri_mesh.h"
#include "util/buffer_pool.h"

namespace filigree {
struct Hierarchy;
class DeformerModel;
}  // namespace filigree

namespace filigree::server {

class MeshWire;
class LevelGeometries;

// The rest mesh as clients receive it: positions (float) and faces, in
// original order, without uploaded_ids.
v1::RestMesh rest_mesh_message(const Hierarchy& h);

// A pose may move the base this many times the rest mesh's bounding-box
// diagonal away from where the mesh lies (see SessionAssets::pose_reach).
inline constexpr double kPoseReachSizes = 1e4;

struct SessionAssets {
  std::shared_ptr<const DeformerModel> model;
  v1::BaseMesh base;
  // SessionInfo's base and rest (positions and faces) as wire bytes; a
  // session adds its upload's ids when it answers.
  std::shared_ptr<const MeshWire> info_wire;
  double rest_diagonal = 1.0;
  // Automatic quantization (SessionOptions.quantization_bits = 0) keeps every
  // coordinate's error within this: 5e-5 of rest_diagonal.
  double automatic_max_error = 0.0;
  // How far from the origin a posed base coordinate may be: the rest mesh's
  // farthest coordinate plus kPoseReachSizes times its size. Farther poses
  // are refused: the deformation of a mesh posed beyond float's useful
  // range fails in compute, after the pose was acknowledged.
  double pose_reach = 0.0;
  // Vertices per frame chunk, the same for every session of the mesh (see
  // chunk_vertices_for in session_assets.cpp).
  std::uint32_t chunk_vertices = 0;
  // Scratch the sessions of this mesh take in turn, so that an idle session
  // holds none (issue 10: a further session ≤ 64 B/vertex): frame positions
  // from compute to quantization, chunk deltas from quantization to encoding.
  std::shared_ptr<BufferPool<Vec3>> frames;
  std::shared_ptr<BufferPool<float>> staging;
  // Frames' wire bytes (SerializedFrame), from publishing until the last
  // stream has written them.
  std::shared_ptr<BufferPool<char>> wire;
  // The levels of detail streams asked for (built on demand).
  std::shared_ptr<LevelGeometries> levels;

  const Hierarchy& hierarchy() const;
};

// The frame encoder's options for a session of these assets with `options`
// (its full frames and its levels of detail alike).
FrameEncoderOptions frame_encoder_options(const v1::SessionOptions& options, const SessionAssets& assets);

class SessionAssetsCache {
 public:
  // The assets of `h`: the ones live sessions already share, or new ones
  // for frames encoded on `threads` threads (which sets their chunk size).
  std::shared_ptr<const SessionAssets> get(const std::shared_ptr<const Hierarchy>& h, std::size_t threads);
  // Hierarchies with live assets (for tests and stats).
  std::size_t live() const;
  // The maintenance loop's: meshes whose scratch pools saw no use since the
  // last call give back what they kept beyond their minimum (BufferPool::
  // trim_if_idle). Returns the buffers freed.
  std::size_t trim_idle_pools();

 private:
  mutable std::mutex mutex_;
  // By address: live assets keep their hierarchy alive, so an address is
  // reused only after its entry has expired.
  std::map<const Hierarchy*, std::weak_ptr<const SessionAssets>> assets_;
};

}  // namespace filigree::server
