#include "runtime/handle_solver.h"

#include <cmath>
#include <stdexcept>

#include <Eigen/SparseCholesky>

#include "geometry/best_fit_rotation.h"
#include "geometry/cotangent_laplacian.h"

namespace filigree {
namespace {

// Handles pull this much harder than the rigidity of one edge of weight 1.
constexpr double kHandleWeight = 1e4;

}  // namespace

struct HandleSolver::System {
  CotangentLaplacian laplacian;
  // The handle points the factorisation was built for (face, bary); the
  // targets may change without refactorising.
  std::vector<std::pair<Index, Vec3>> points;
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver;
};

HandleSolver::HandleSolver(TriMesh base) : base_(std::move(base)), system_(std::make_unique<System>()) {
  system_->laplacian = cotangent_laplacian(base_);
}

HandleSolver::~HandleSolver() = default;

Pose HandleSolver::solve(const std::vector<HandleTarget>& handles, const Pose& start, int iterations) {
  const std::size_t m = base_.positions.size();
  validate_pose(start, m);
  if (handles.empty()) return start;
  for (const HandleTarget& h : handles) {
    if (h.base_face >= base_.faces.size()) throw std::invalid_argument("handle on base face " + std::to_string(h.base_face) + ", out of range");
    if (!h.target.allFinite() || !h.bary.allFinite()) throw std::invalid_argument("handle target or coordinates are not finite");
  }
  System& s = *system_;
  const CotangentLaplacian& L = s.laplacian;

  std::vector<std::pair<Index, Vec3>> points;
  for (const HandleTarget& h : handles) points.emplace_back(h.base_face, h.bary);
  if (points != s.points || s.solver.rows() == 0) {
    // A = L + w Σ_h b_h b_hᵀ: symmetric positive definite once a handle pins
    // the translation (L alone is only semi-definite).
    std::vector<Eigen::Triplet<double>> entries;
    for (Index i = 0; i < m; ++i) {
      double diagonal = 0.0;
      for (Index k = L.offsets[i]; k < L.offsets[i + 1]; ++k) {
        entries.emplace_back(i, L.neighbors[k], -L.weights[k]);
        diagonal += L.weights[k];
      }
      entries.emplace_back(i, i, diagonal);
    }
    for (const HandleTarget& h : handles) {
      const Triangle& f = base_.faces[h.base_face];
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b) entries.emplace_back(f[a], f[b], kHandleWeight * h.bary[a] * h.bary[b]);
    }
    Eigen::SparseMatrix<double> a(static_cast<int>(m), static_cast<int>(m));
    a.setFromTriplets(entries.begin(), entries.end());
    s.solver.compute(a);
    if (s.solver.info() != Eigen::Success) throw std::runtime_error("handle system could not be factorised");
    s.points = std::move(points);
    ++factorizations_;
  }

  std::vector<Vec3> x = start.positions;
  const std::vector<Vec3>& rest = base_.positions;
  std::vector<Eigen::Matrix3d> rotation(m);
  Eigen::MatrixX3d rhs(static_cast<Eigen::Index>(m), 3);
  for (int it = 0; it < std::max(iterations, 1); ++it) {
    // Local step: the best rotation of each 1-ring onto its current shape.
    for (Index i = 0; i < m; ++i) {
      Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
      for (Index k = L.offsets[i]; k < L.offsets[i + 1]; ++k) {
        const Index j = L.neighbors[k];
        cov += L.weights[k] * (rest[i] - rest[j]) * (x[i] - x[j]).transpose();
      }
      rotation[i] = best_fit_rotation(cov);
    }
    // Global step: Σ_j w_ij (x_i − x_j) = Σ_j w_ij (R_i + R_j)/2 (r_i − r_j), plus the handles.
    for (Index i = 0; i < m; ++i) {
      Vec3 b = Vec3::Zero();
      for (Index k = L.offsets[i]; k < L.offsets[i + 1]; ++k) {
        const Index j = L.neighbors[k];
        b += 0.5 * L.weights[k] * (rotation[i] + rotation[j]) * (rest[i] - rest[j]);
      }
      rhs.row(i) = b.transpose();
    }
    for (const HandleTarget& h : handles) {
      const Triangle& f = base_.faces[h.base_face];
      for (int a = 0; a < 3; ++a) rhs.row(f[a]) += (kHandleWeight * h.bary[a] * h.target).transpose();
    }
    const Eigen::MatrixX3d solution = s.solver.solve(rhs);
    for (Index i = 0; i < m; ++i) x[i] = solution.row(i).transpose();
  }
  return Pose{std::move(x)};
}

}  // namespace filigree
