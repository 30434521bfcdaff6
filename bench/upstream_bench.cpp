// Upstream bytes per frame: a skeletal pose (DriveRequest.joints) against the
// same pose sent as base positions, on the demo mesh (issue 13).
//
//   filigree_bench_upstream [MESH] [--joints N]
//
// The base size is the server's default for the mesh (default_base_vertices);
// positions and joint values are float32 on the wire whatever they hold, so
// the sizes are those of real requests of this session's shape.

#include <cstdio>
#include <cstdlib>
#include <string>

#include "filigree/v1/filigree.pb.h"
#include "mesh/mesh_io.h"
#include "preprocess/preprocess.h"
#include "skinning/auto_rig.h"
#include "skinning/skinning.h"

int main(int argc, char** argv) {
  using namespace filigree;
  std::string path = FILIGREE_REPO_DATA_DIR "/armadillo.off";
  std::size_t joints = 8;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--joints" && i + 1 < argc) joints = std::strtoul(argv[++i], nullptr, 10);
    else path = a;
  }
  const TriMesh mesh = read_mesh(path);
  const Rig rig = auto_rig(mesh, {.joints = joints});
  const std::size_t m = default_base_vertices(mesh.vertex_count());

  // The skinned base: what a client skinning the base itself sends.
  SkeletonPose pose = SkeletonPose::rest(rig);
  std::vector<Vec3> skinned(rig.vertex_count());
  skin(rig, model_transforms(rig, pose), SkinningMethod::kLinearBlend, skinned);
  v1::DriveRequest positions;
  positions.set_pose_id(123456);
  for (std::size_t i = 0; i < m; ++i)
    for (int k = 0; k < 3; ++k) positions.add_positions(static_cast<float>(skinned[i][k]));

  v1::DriveRequest all_joints;
  all_joints.set_pose_id(123456);
  for (const Joint& j : rig.joints)
    for (const double c : {j.rest.translation.x(), j.rest.translation.y(), j.rest.translation.z(), j.rest.rotation.x(),
                           j.rest.rotation.y(), j.rest.rotation.z(), j.rest.rotation.w(), 1.0, 1.0, 1.0})
      all_joints.mutable_joints()->add_values(static_cast<float>(c));
  v1::DriveRequest two_joints;  // a partial pose: an arm, say
  two_joints.set_pose_id(123456);
  for (std::uint32_t j = 1; j <= 2; ++j) {
    two_joints.mutable_joints()->add_joint_indices(j);
    for (int k = 0; k < 10; ++k) two_joints.mutable_joints()->add_values(k == 6 ? 1.0f : 0.0f);
  }
  const double p = static_cast<double>(positions.ByteSizeLong());
  std::printf("mesh %s: %zu vertices, base %zu vertices, %zu joints\n", path.c_str(), mesh.vertex_count(), m, joints);
  std::printf("upstream bytes per frame: positions %zu, skeletal (all joints, TRS) %zu (%.1fx fewer), "
              "skeletal (2 joints) %zu (%.1fx fewer)\n",
              positions.ByteSizeLong(), all_joints.ByteSizeLong(), p / static_cast<double>(all_joints.ByteSizeLong()),
              two_joints.ByteSizeLong(), p / static_cast<double>(two_joints.ByteSizeLong()));
  return 0;
}
