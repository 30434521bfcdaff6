// Writes the seed corpora of tests/fuzz/corpus/ (small, valid inputs of every
// target, made with the project's own writers so they stay in step with the
// formats). Usage: fuzz_make_seeds CORPUS_DIR. Run by hand when a format
// changes; the seeds are committed.

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "codec/delta_codec.h"
#include "codec/delta_quantization.h"
#include "codec/level_mesh_codec.h"
#include "filigree/v1/filigree.pb.h"
#include "hierarchy/hierarchy_file.h"
#include "mesh/gltf_io.h"
#include "mesh/mesh_io.h"
#include "preprocess/preprocess.h"
#include "runtime/pose_io.h"
#include "server/http/grpc_web_bridge.h"
#include "server/session_record.h"
#include "skinning/auto_rig.h"
#include "skinning/rig_file.h"

namespace fs = std::filesystem;
using namespace filigree;

namespace {

void put(const fs::path& path, const std::string& bytes) {
  fs::create_directories(path.parent_path());
  std::ofstream(path, std::ios::binary) << bytes;
}

std::string slurp(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

TriMesh grid(int n) {
  TriMesh m;
  for (int i = 0; i <= n; ++i)
    for (int j = 0; j <= n; ++j)
      m.positions.emplace_back(double(i) / n, double(j) / n, 0.1 * std::sin(3.0 * i / n) * std::cos(2.0 * j / n));
  const auto id = [&](int i, int j) { return static_cast<Index>(i * (n + 1) + j); };
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      m.faces.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
      m.faces.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
    }
  return m;
}

// A frame of `values` (3 per vertex) in one Draco buffer (FRAME_FORMAT_SINGLE).
v1::Frame single_frame(const std::vector<float>& values, std::uint64_t version) {
  DeltaQuantization q;
  q.bits = 12;
  q.min = -1.0f;
  q.range = 2.0f;
  v1::Frame f;
  f.set_version(version);
  f.set_vertex_count(static_cast<std::uint32_t>(values.size() / 3));
  f.set_quantization_bits(q.bits);
  f.set_delta_min(q.min);
  f.set_delta_range(q.range);
  f.set_deltas(encode_draco(values, q));
  return f;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: fuzz_make_seeds CORPUS_DIR\n");
    return 2;
  }
  const fs::path out = argv[1], tmp = fs::temp_directory_path() / "filigree_fuzz_seeds";
  fs::create_directories(tmp);
  const TriMesh small = grid(3);
  for (const char* ext : {"obj", "ply"}) {  // write_mesh writes these (and .glb)
    write_mesh(small, tmp / (std::string("grid.") + ext));
    put(out / ext / "grid", slurp(tmp / (std::string("grid.") + ext)));
  }
  std::string off = "OFF\n" + std::to_string(small.positions.size()) + " " + std::to_string(small.faces.size()) + " 0\n";
  for (const Vec3& p : small.positions) off += std::to_string(p.x()) + " " + std::to_string(p.y()) + " " + std::to_string(p.z()) + "\n";
  for (const Triangle& f : small.faces) off += "3 " + std::to_string(f[0]) + " " + std::to_string(f[1]) + " " + std::to_string(f[2]) + "\n";
  put(out / "off" / "grid", off);
  put(out / "obj" / "quad_and_junk", "# a comment\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nf 1/1/1 2//1 3\nf 1 3 4\n");
  put(out / "ply" / "ascii", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                             "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");

  // A skinned GLB (the automatic rig and its clips), and a glTF with its buffer inline.
  const TriMesh mid = grid(6);
  AutoRigOptions rig_options;
  rig_options.joints = 3;
  const Rig rig = auto_rig(mid, rig_options);
  write_glb_rigged(mid, rig, tmp / "rigged.glb");
  put(out / "glb" / "rigged", slurp(tmp / "rigged.glb"));
  write_mesh(small, tmp / "grid.glb");
  put(out / "glb" / "plain", slurp(tmp / "grid.glb"));
  put(out / "gltf" / "triangle",
      R"({"asset":{"version":"2.0"},"scenes":[{"nodes":[0]}],"nodes":[{"mesh":0}],)"
      R"("meshes":[{"primitives":[{"attributes":{"POSITION":0}}]}],)"
      R"("accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}],)"
      R"("bufferViews":[{"buffer":0,"byteLength":36}],)"
      R"("buffers":[{"byteLength":36,"uri":"data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA"}]})");

  PreprocessOptions options;
  options.base_vertices = 12;
  const Hierarchy h = preprocess(mid, options);
  put(out / "hierarchy_file" / "grid", serialize_hierarchy(h));
  put(out / "rig_file" / "auto_rig", serialize_rig(rig));

  // Pose files: the first byte is (base vertices · 4 + extension index).
  Pose pose;
  pose.positions.assign(small.positions.begin(), small.positions.end());
  write_pose(pose, tmp / "grid.pose");
  put(out / "pose_file" / "pose", std::string(1, static_cast<char>(small.positions.size() * 4 + 0)) + slurp(tmp / "grid.pose"));
  put(out / "pose_file" / "obj", std::string(1, static_cast<char>(small.positions.size() * 4 + 1)) + slurp(tmp / "grid.obj"));

  // Frames: a single-buffer frame, then a chunked keyframe and a sparse frame on it.
  const std::size_t n = 40;
  std::vector<float> values(3 * n);
  for (std::size_t i = 0; i < values.size(); ++i) values[i] = 0.5f * std::sin(0.3f * float(i));
  const std::string single = single_frame(values, 1).SerializeAsString();
  put(out / "frame" / "single", std::string(1, static_cast<char>((single.size() + 15) / 16)) +
                                    single + std::string(16 * ((single.size() + 15) / 16) - single.size(), '\0'));
  v1::Frame key = single_frame(values, 2), sparse = single_frame(std::vector<float>(values.begin(), values.begin() + 30), 3);
  v1::DeltaChunk* kc = key.add_chunks();
  kc->set_first_vertex(0);
  kc->set_vertex_count(static_cast<std::uint32_t>(n));
  kc->set_deltas(key.deltas());
  kc->set_quantization_bits(key.quantization_bits());
  kc->set_delta_min(key.delta_min());
  kc->set_delta_range(key.delta_range());
  key.clear_deltas();
  key.set_keyframe_version(2);
  v1::DeltaChunk* sc = sparse.add_chunks();
  sc->set_first_vertex(0);
  sc->set_vertex_count(static_cast<std::uint32_t>(n));
  for (std::uint32_t r : {5u, 10u}) sc->add_runs(r);  // skip 5, take 10
  sc->set_deltas(sparse.deltas());
  sc->set_quantization_bits(sparse.quantization_bits());
  sc->set_delta_min(sparse.delta_min());
  sc->set_delta_range(sparse.delta_range());
  sparse.clear_deltas();
  sparse.set_vertex_count(static_cast<std::uint32_t>(n));
  sparse.set_keyframe_version(2);
  const std::string k = key.SerializeAsString();
  put(out / "frame" / "chunked", std::string(1, static_cast<char>((k.size() + 15) / 16)) + k +
                                     std::string(16 * ((k.size() + 15) / 16) - k.size(), '\0') +
                                     sparse.SerializeAsString());

  // A level of detail: the first message starts it (the 16 vertices of a 3×3
  // grid's mesh, ids into the 40-vertex mesh), the second is a frame of it.
  LevelMesh level_mesh;
  for (std::uint32_t i = 0; i < 16; ++i) level_mesh.original_ids.push_back(2 * i);
  for (const Triangle& f : small.faces)
    for (Index v : f) level_mesh.faces.push_back(static_cast<std::uint32_t>(v));
  v1::Frame start;
  start.set_vertex_count(static_cast<std::uint32_t>(n));
  start.mutable_level()->set_vertex_count(16);
  start.mutable_level()->set_face_count(static_cast<std::uint32_t>(small.faces.size()));
  start.mutable_level()->set_mesh(encode_level_mesh(level_mesh));
  v1::Frame at_level = single_frame(std::vector<float>(values.begin(), values.begin() + 48), 4);
  at_level.set_level_vertices(16);
  const std::string s = start.SerializeAsString();
  put(out / "frame" / "level", std::string(1, static_cast<char>((s.size() + 15) / 16)) + s +
                                   std::string(16 * ((s.size() + 15) / 16) - s.size(), '\0') +
                                   at_level.SerializeAsString());

  put(out / "grpc_web" / "message", server::http::encode_frame(0, std::string("\x0a\x05hello", 7)));
  put(out / "grpc_web" / "empty", server::http::encode_frame(0, ""));

  server::SessionRecord record;
  record.id = "0123456789abcdef0123";
  record.hierarchy_key = "grid";
  record.editor_token = "not-a-secret-editor";
  record.viewer_token = "not-a-secret-viewer";
  record.pose.assign(36, 0.25f);
  record.version = 7;
  record.uploaded_ids = {0, 2, 1};
  record.rig = serialize_rig(rig);
  put(out / "session_record" / "record", server::encode_session_record(record));
  server::SessionProgress progress;
  progress.pose.assign(36, 0.5f);
  progress.version = 8;
  put(out / "session_record" / "progress", server::encode_session_progress(progress));
  fs::remove_all(tmp);
  std::printf("seeds written under %s\n", out.c_str());
  return 0;
}
