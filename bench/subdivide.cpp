#include "bench/subdivide.h"

#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>
#include <OpenMesh/Tools/Subdivider/Uniform/LoopT.hh>
#include <OpenMesh/Tools/Subdivider/Uniform/Sqrt3T.hh>

namespace filigree::bench {

using OMesh = OpenMesh::TriMesh_ArrayKernelT<>;

TriMesh subdivide(const TriMesh& mesh, int loop, int sqrt3) {
  OMesh om;
  std::vector<OMesh::VertexHandle> vh;
  for (const Vec3& p : mesh.positions) vh.push_back(om.add_vertex(OMesh::Point(p.x(), p.y(), p.z())));
  for (const Triangle& f : mesh.faces) om.add_face(vh[f[0]], vh[f[1]], vh[f[2]]);
  if (loop > 0) {
    OpenMesh::Subdivider::Uniform::LoopT<OMesh> subdivider;
    subdivider.attach(om);
    subdivider(static_cast<std::size_t>(loop));
    subdivider.detach();
  }
  if (sqrt3 > 0) {
    OpenMesh::Subdivider::Uniform::Sqrt3T<OMesh> subdivider;
    subdivider.attach(om);
    subdivider(static_cast<std::size_t>(sqrt3));
    subdivider.detach();
  }
  om.garbage_collection();
  TriMesh out;
  for (auto v : om.vertices()) {
    const auto p = om.point(v);
    out.positions.emplace_back(p[0], p[1], p[2]);
  }
  for (auto f : om.faces()) {
    Triangle t;
    int c = 0;
    for (auto v : om.fv_range(f)) t[c++] = static_cast<Index>(v.idx());
    out.faces.push_back(t);
  }
  return out;
}

}  // namespace filigree::bench
