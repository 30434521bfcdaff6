#pragma once
// What the service benchmarks share (service_bench.cpp, history_bench.cpp):
// a server of the bench's own, its meshes by size, uploading one, the two
// motions' poses, and the closed-loop drive that times pose → frame.

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "filigree/v1/filigree.grpc.pb.h"
#include "mesh/tri_mesh.h"
#include "support/server_process.h"

namespace filigree::bench {

using Clock = std::chrono::steady_clock;

// The first frames of each drive (its stream's set-up, the first keyframe),
// timed apart from the rest.
constexpr int kWarmupFrames = 8;

struct Result {
  double first = 0, p50 = 0, p99 = 0, fps = 0, compute_p50 = 0, compute_p99 = 0, encode_p50 = 0, both_p99 = 0,
         bytes_per_vertex = 0, max_error_rel = 0, present = 0, other_p50 = 0;
  std::size_t watcher_frames = 0;
};

// Bytes of a frame's deltas on the wire, either format.
std::size_t delta_bytes(const v1::Frame& f);

enum class Movement { kWholeBody, kLocal };

// The bench's two motions on a session's base mesh: a whole-body bend (full
// poses), and a bump of 2% of the diagonal under the base vertices within 8%
// of the diagonal from base vertex 0, rising and falling (a sculpted or
// dragged detail, sent as partial poses).
class MotionPoses {
 public:
  explicit MotionPoses(const v1::CreateSessionResponse::Created& created);
  // Pose p of `motion`: its indices (the bump's) and positions into r.
  void fill(v1::DriveRequest& r, Movement motion, int p) const;
  std::size_t bumped() const { return bumped_.size(); }

 private:
  std::vector<Vec3> base_rest_;
  double diag_ = 0.0;
  std::vector<std::uint32_t> bumped_;
};

// A call's context with the session's id and a token.
std::unique_ptr<grpc::ClientContext> context(const std::string& id, const std::string& token);

// `poses` closed-loop poses of `motion` on one Drive stream (send a pose,
// wait for the frame that answers it), after kWarmupFrames timed apart,
// with `watchers` Watch streams reading as fast as they can.
Result run(v1::Filigree::Stub& stub, const v1::CreateSessionResponse::Created& created, int watchers, int poses,
           Movement motion = Movement::kWholeBody, v1::FrameFormat format = v1::FRAME_FORMAT_CHUNKED);

// The mesh as OBJ bytes, for upload().
std::string obj_bytes(const TriMesh& mesh);
// The mesh as a binary PLY file's bytes, float32 coordinates (what a scan
// of millions of vertices is usually shipped as: a third of the OBJ).
std::string ply_bytes(const TriMesh& mesh);
// A process's resident memory (VmRSS), in bytes.
double resident_bytes(int pid);
// A process's peak resident memory so far (VmHWM), in bytes.
double peak_resident_bytes(int pid);
// CreateSession with OBJ bytes; throws when the server refuses.
v1::CreateSessionResponse::Created upload(v1::Filigree::Stub& stub, const std::string& bytes);

// A server of the bench's own on a fresh data directory (and `extra` flags),
// and a stub with the client library's channel settings: no limit on a
// SessionInfo's size, and a fixed frame window (filigree/channel_arguments.h;
// with gRPC's adaptive one a 1.25M frame took 3 ms more to arrive). Stopped,
// its data removed, when destroyed. Messages up to 256 MiB (a SessionInfo
// carries its rest mesh whole), unless `default_limits`: then the server's
// own limits, as a user starts it (64 MiB messages: a rest mesh over 32 MiB
// comes from GetRestMesh in parts, which upload() does not read).
struct BenchServer {
  BenchServer(const std::string& binary, const std::string& tag, const std::vector<std::string>& extra = {},
              bool default_limits = false);
  ~BenchServer();
  BenchServer(const BenchServer&) = delete;
  BenchServer& operator=(const BenchServer&) = delete;

  std::filesystem::path data;
  test::ServerProcess server;
  std::unique_ptr<v1::Filigree::Stub> stub;
};

// The bench's meshes by size: "small" ≈10k and "medium" ≈150k (the real
// camel, and the bunny scan subdivided once: no real mesh of that size here
// is manifold) when the shared meshes are there, else the shipped Armadillo
// and its subdivision; "large" ≥ 1M (the Armadillo subdivided, Loop twice
// and √3 once, 1.25M), in locality order; "huge" ≥ 2M (bumpy_uv_sphere:
// 2,000,002 vertices, 4,000,000 faces).
struct Case {
  std::string name;
  TriMesh mesh;
};
Case bench_mesh(const std::string& size);

// A closed UV ellipsoid (1.5 : 1 : 1 along x, y, z) with bumps at two
// scales, r(θ, φ) = 1 + 0.05·sin 5θ·cos 4φ + 0.01·sin 40θ·sin 40φ: `rings`
// rings of `segments` vertices between the two poles, 2 + rings·segments
// vertices and 2·rings·segments faces, outward. bench/service_large_mesh.py
// builds the same mesh for the Python side.
TriMesh bumpy_uv_sphere(int rings, int segments);

}  // namespace filigree::bench
