#pragma once
// A rotation per base vertex from its 1-ring, rest vs posed (DESIGN §2.2.1).

#include <vector>

#include <Eigen/Geometry>

#include "mesh/tri_mesh.h"

namespace filigree {

enum class RotationMethod {
  // Best-fit rotation of the whole 1-ring (SVD of the edge covariance, as in
  // ARAP). The default: it uses every ring edge, so one noisy edge does not
  // swing the frame. Measured (bench/runtime_bench, Armadillo, whole-mesh
  // optimisation): mean edge-length distortion 11.55% vs 12.18% (bend),
  // 6.92% vs 7.18% (twist) for the local frame, for 0.45 vs 0.06 ms per frame.
  kBestFit,
  // The thesis' local frame (eq. 3.1): normal, the ring edge closest to it,
  // and their cross product; R = L2 · L1ᵀ.
  kLocalFrame,
};

const char* to_string(RotationMethod m);

class BaseRotations {
 public:
  // `base` is the base mesh in base order (Hierarchy::base_mesh()).
  BaseRotations(const TriMesh& base, RotationMethod method);

  // One unit quaternion per base vertex, mapping rest ring directions to
  // posed; computed on `threads` threads, the result does not depend on it.
  void compute(const std::vector<Vec3>& posed, std::vector<Eigen::Quaterniond>& out, int threads = 1) const;

 private:
  Eigen::Matrix3d local_frame(const std::vector<Vec3>& x, Index v) const;

  RotationMethod method_;
  std::vector<Vec3> rest_;
  std::vector<Index> offsets_, neighbors_;  // 1-ring, CSR
  std::vector<Index> face_offsets_, faces_;  // incident faces, CSR
  std::vector<Triangle> triangles_;
  std::vector<Index> frame_edge_;             // kLocalFrame only: the ring vertex of the frame edge
  std::vector<Eigen::Matrix3d> rest_frames_;  // kLocalFrame only
};

}  // namespace filigree
