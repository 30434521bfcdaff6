#pragma once
// Editing by handles (issue 5): points on the detailed mesh dragged to
// targets become a base pose through an as-rigid-as-possible solve on the base
// mesh (Sorkine & Alexa 2007), which then runs through the normal pipeline.

#include <memory>
#include <vector>

#include "mesh/tri_mesh.h"
#include "runtime/pose.h"

namespace filigree {

// A handle, expressed on the base mesh: a point with barycentric coordinates
// in a base face (a vertex's MAPS coordinates), and where it should go.
struct HandleTarget {
  Index base_face = 0;
  Vec3 bary = Vec3(1, 0, 0);
  Vec3 target = Vec3::Zero();
};

class HandleSolver {
 public:
  // `base` is the base rest mesh in base order.
  explicit HandleSolver(TriMesh base);
  ~HandleSolver();
  HandleSolver(const HandleSolver&) = delete;
  HandleSolver& operator=(const HandleSolver&) = delete;

  // The base pose that keeps every 1-ring as rigid as possible while the
  // handles (soft constraints, weight 1e4 relative to the Laplacian) reach
  // their targets; `iterations` local–global steps starting from `start`.
  // The factorisation is kept while the set of handle points is unchanged.
  // Throws std::invalid_argument for an out-of-range face or NaN target.
  Pose solve(const std::vector<HandleTarget>& handles, const Pose& start, int iterations = 8);

  std::size_t factorizations() const { return factorizations_; }

 private:
  struct System;
  TriMesh base_;
  std::unique_ptr<System> system_;
  std::size_t factorizations_ = 0;
};

}  // namespace filigree
