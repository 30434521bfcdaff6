#include "runtime/base_rotations.h"

#include <algorithm>

#include "geometry/best_fit_rotation.h"
#include "util/parallel_for.h"

namespace filigree {

const char* to_string(RotationMethod m) { return m == RotationMethod::kBestFit ? "best-fit" : "local-frame"; }

BaseRotations::BaseRotations(const TriMesh& base, RotationMethod method)
    : method_(method), rest_(base.positions), triangles_(base.faces) {
  const std::size_t m = base.positions.size();
  std::vector<std::vector<Index>> ring(m), incident(m);
  for (Index f = 0; f < base.faces.size(); ++f) {
    const Triangle& t = base.faces[f];
    for (int c = 0; c < 3; ++c) {
      ring[t[c]].push_back(t[(c + 1) % 3]);
      ring[t[c]].push_back(t[(c + 2) % 3]);
      incident[t[c]].push_back(f);
    }
  }
  offsets_ = {0};
  face_offsets_ = {0};
  for (std::size_t v = 0; v < m; ++v) {
    std::sort(ring[v].begin(), ring[v].end());
    ring[v].erase(std::unique(ring[v].begin(), ring[v].end()), ring[v].end());
    neighbors_.insert(neighbors_.end(), ring[v].begin(), ring[v].end());
    offsets_.push_back(static_cast<Index>(neighbors_.size()));
    faces_.insert(faces_.end(), incident[v].begin(), incident[v].end());
    face_offsets_.push_back(static_cast<Index>(faces_.size()));
  }
  if (method_ == RotationMethod::kLocalFrame) {
    // The ring edge closest to the normal (thesis §3.1.2), chosen once on the
    // rest mesh so that rest and posed frames are built from the same edge.
    frame_edge_.resize(m);
    for (Index v = 0; v < m; ++v) {
      Vec3 normal = Vec3::Zero();
      for (Index k = face_offsets_[v]; k < face_offsets_[v + 1]; ++k) {
        const Triangle& t = triangles_[faces_[k]];
        normal += (rest_[t[1]] - rest_[t[0]]).cross(rest_[t[2]] - rest_[t[0]]);
      }
      normal.normalize();
      double best_cos = -2.0;
      for (Index k = offsets_[v]; k < offsets_[v + 1]; ++k) {
        const double c = std::abs((rest_[neighbors_[k]] - rest_[v]).normalized().dot(normal));
        if (c > best_cos) best_cos = c, frame_edge_[v] = neighbors_[k];
      }
    }
    rest_frames_.resize(m);
    for (Index v = 0; v < m; ++v) rest_frames_[v] = local_frame(rest_, v);
  }
}

Eigen::Matrix3d BaseRotations::local_frame(const std::vector<Vec3>& x, Index v) const {
  Vec3 normal = Vec3::Zero();
  for (Index k = face_offsets_[v]; k < face_offsets_[v + 1]; ++k) {
    const Triangle& t = triangles_[faces_[k]];
    normal += (x[t[1]] - x[t[0]]).cross(x[t[2]] - x[t[0]]);
  }
  normal.normalize();
  const Index best = frame_edge_[v];
  Vec3 edge = x[best] - x[v];
  Vec3 side = normal.cross(edge).normalized();
  Eigen::Matrix3d frame;
  frame.col(0) = normal;
  frame.col(1) = side;
  frame.col(2) = side.cross(normal);
  return frame;
}

void BaseRotations::compute(const std::vector<Vec3>& posed, std::vector<Eigen::Quaterniond>& out, int threads) const {
  const std::size_t m = rest_.size();
  out.resize(m);
  parallel_for(m, threads, [&](std::size_t i) {
    const Index v = static_cast<Index>(i);
    Eigen::Matrix3d r;
    if (method_ == RotationMethod::kLocalFrame) {
      r = local_frame(posed, v) * rest_frames_[v].transpose();
    } else {
      Eigen::Matrix3d s = Eigen::Matrix3d::Zero();
      for (Index k = offsets_[v]; k < offsets_[v + 1]; ++k) {
        const Index j = neighbors_[k];
        s += (rest_[j] - rest_[v]) * (posed[j] - posed[v]).transpose();
      }
      r = best_fit_rotation(s);
    }
    out[v] = Eigen::Quaterniond(r).normalized();
    if (!out[v].coeffs().allFinite()) out[v] = Eigen::Quaterniond::Identity();  // degenerate ring
  });
}

}  // namespace filigree
