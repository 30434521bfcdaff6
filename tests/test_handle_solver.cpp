// Handles → base pose by an as-rigid-as-possible solve on the base mesh.

#include <gtest/gtest.h>

#include "runtime/handle_solver.h"
#include "support/test_meshes.h"

namespace filigree {
namespace {

Vec3 point(const TriMesh& m, const HandleTarget& h, const std::vector<Vec3>& x) {
  const Triangle& f = m.faces[h.base_face];
  return h.bary[0] * x[f[0]] + h.bary[1] * x[f[1]] + h.bary[2] * x[f[2]];
}

class HandleSolverTest : public ::testing::Test {
 protected:
  TriMesh base_ = test::icosphere(2);  // 162 vertices
  Pose rest_{base_.positions};
  HandleTarget handle(Index face, Vec3 bary, const Vec3& offset) const {
    HandleTarget h{face, bary, Vec3::Zero()};
    h.target = point(base_, h, base_.positions) + offset;
    return h;
  }
};

TEST_F(HandleSolverTest, HandlesAtRestGiveTheRestPose) {
  HandleSolver solver(base_);
  const Pose p = solver.solve({handle(0, Vec3(0.2, 0.3, 0.5), Vec3::Zero()), handle(100, Vec3(1, 0, 0), Vec3::Zero())}, rest_);
  for (std::size_t i = 0; i < p.positions.size(); ++i) EXPECT_LT((p.positions[i] - rest_.positions[i]).norm(), 1e-9);
}

TEST_F(HandleSolverTest, OneHandleMovesTheBaseRigidly) {
  HandleSolver solver(base_);
  const Vec3 t(0.3, -0.2, 0.7);
  const Pose p = solver.solve({handle(5, Vec3(1.0 / 3, 1.0 / 3, 1.0 / 3), t)}, rest_);
  for (std::size_t i = 0; i < p.positions.size(); ++i) EXPECT_LT((p.positions[i] - (rest_.positions[i] + t)).norm(), 1e-6);
}

TEST_F(HandleSolverTest, TwoHandlesReachTheirTargetsAndRefactoriseOnlyForNewPoints) {
  HandleSolver solver(base_);
  // Opposite faces pulled apart along the line between them.
  const Vec3 a = point(base_, {0, Vec3(1, 0, 0), {}}, base_.positions);
  Index far = 0;
  double best = 0.0;
  for (Index f = 0; f < base_.faces.size(); ++f) {
    const double d = (base_.positions[base_.faces[f][0]] - a).norm();
    if (d > best) best = d, far = f;
  }
  const Vec3 dir = (base_.positions[base_.faces[far][0]] - a).normalized();
  std::vector<HandleTarget> hs = {handle(0, Vec3(1, 0, 0), -0.3 * dir), handle(far, Vec3(1, 0, 0), 0.3 * dir)};
  const Pose p = solver.solve(hs, rest_, 20);
  for (const HandleTarget& h : hs) EXPECT_LT((point(base_, h, p.positions) - h.target).norm(), 0.02);
  EXPECT_EQ(solver.factorizations(), 1u);
  // Same points, new targets: no new factorisation.
  hs[1].target += 0.1 * dir;
  solver.solve(hs, p);
  EXPECT_EQ(solver.factorizations(), 1u);
  hs.push_back(handle(50, Vec3(0, 1, 0), Vec3::Zero()));
  solver.solve(hs, p);
  EXPECT_EQ(solver.factorizations(), 2u);
}

TEST_F(HandleSolverTest, BadHandlesAreRejected) {
  HandleSolver solver(base_);
  EXPECT_THROW(solver.solve({HandleTarget{100000, Vec3(1, 0, 0), Vec3::Zero()}}, rest_), std::invalid_argument);
  EXPECT_THROW(solver.solve({HandleTarget{0, Vec3(1, 0, 0), Vec3(std::nan(""), 0, 0)}}, rest_), std::invalid_argument);
  EXPECT_EQ(solver.solve({}, rest_).positions, rest_.positions);
}

}  // namespace
}  // namespace filigree
