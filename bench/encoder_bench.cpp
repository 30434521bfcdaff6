// Frame encoding on one thread, without the service around it (issue 11): the
// shipped Armadillo and its subdivisions (26k, 104k, 1.25M vertices, in
// locality order, as the server orders them) under an analytic motion on every
// vertex, encoded by FrameEncoder as keyframes (every vertex sent: the whole-
// body worst case) with automatic quantization (max error 5e-5 of the
// diagonal) in chunks of 16384. Per mesh and motion it prints the quantize
// pass (staging, what moved, the error bound) and the Draco buffers, ours
// (encode_draco) against Draco 1.5's own encoder on the same chunks, in ns
// per vertex; the bytes are checked equal on every chunk. Then the quantize
// pass of the frame just after each keyframe, which a driven session mostly
// sends (compared with the keyframe and the previous frame, usually sparse).
//
// Usage: filigree_bench_encoder [--quick] (the quick run skips the 1.25M mesh)

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <stdexcept>
#include <string>
#include <vector>

#include "bench/sample_stats.h"
#include "bench/subdivide.h"
#include "codec/draco_library_encoder.h"
#include "codec/draco_writer.h"
#include "codec/frame_encoder.h"
#include "mesh/mesh_io.h"
#include "mesh/mesh_validation.h"
#include "mesh/vertex_order.h"
#include "runtime/procedural_motion.h"

namespace {

using namespace filigree;
using Clock = std::chrono::steady_clock;

double ms_since(Clock::time_point t) { return std::chrono::duration<double, std::milli>(Clock::now() - t).count(); }

struct Row {
  double quantize_ns = 0.0, ours_ns = 0.0, grouped_ns = 0.0, draco_ns = 0.0, bytes_per_vertex = 0.0;
  double temporal_quantize_ns = 0.0, temporal_sent = 0.0;
};

// Medians over `rounds` frames at phases 0.3 … 0.9 of `motion`, after one
// untimed round.
Row measure(const TriMesh& mesh, Motion motion, int rounds) {
  const double diag = bounding_box_diagonal(mesh.positions);
  const double n = static_cast<double>(mesh.vertex_count());
  const MotionField field(mesh.positions, motion, 0.0);
  std::vector<double> quantize, ours, grouped, dracos, temporal;
  double sent = 0.0;
  double bytes = 0.0;
  // One encoder for every round, as a session keeps one (its buffers are
  // allocated once; a first round would time the page faults).
  FrameEncoder encoder(mesh.positions, {.max_error = 5e-5 * diag});
  for (int r = -1; r < rounds; ++r) {
    const std::vector<Vec3> posed = field.with_phase(0.3 + 0.6 * std::max(r, 0) / std::max(1, rounds - 1)).apply(mesh.positions);
    encoder.begin(/*force_keyframe=*/true);
    auto t = Clock::now();
    for (std::size_t c = 0; c < encoder.chunk_count(); ++c) encoder.quantize_chunk(c, posed);
    const double quantize_ms = ms_since(t);
    // Both writers on each chunk's staged values; their bytes must be equal.
    // Then ours again over the same chunks, kDracoInterleave at a time.
    double ours_ms = 0.0, draco_ms = 0.0, total = 0.0;
    std::vector<std::string> dracos_bytes(encoder.chunk_count());
    for (std::size_t c = 0; c < encoder.chunk_count(); ++c) {
      t = Clock::now();
      dracos_bytes[c] = encode_with_draco_library(encoder.staged(c), encoder.chunk(c).quantization, kDefaultEncodingSpeed);
      draco_ms += ms_since(t);
      t = Clock::now();
      encoder.encode_chunk(c);
      ours_ms += ms_since(t);
      if (dracos_bytes[c] != encoder.chunk(c).bytes)
        throw std::runtime_error("chunk " + std::to_string(c) + ": our bytes differ from Draco's");
      total += static_cast<double>(dracos_bytes[c].size());
    }
    t = Clock::now();
    for (std::size_t c = 0; c < encoder.chunk_count(); c += kDracoInterleave)
      encoder.encode_chunks(c, std::min(kDracoInterleave, encoder.chunk_count() - c));
    const double grouped_ms = ms_since(t);
    for (std::size_t c = 0; c < encoder.chunk_count(); ++c)
      if (dracos_bytes[c] != encoder.chunk(c).bytes)
        throw std::runtime_error("chunk " + std::to_string(c) + ": our interleaved bytes differ from Draco's");
    encoder.finish();
    // The frame after it, against that keyframe (what a driven session
    // mostly sends): the quantize pass compares every delta with the
    // keyframe and the previous frame.
    const std::vector<Vec3> next = field.with_phase(0.31 + 0.6 * std::max(r, 0) / std::max(1, rounds - 1)).apply(mesh.positions);
    encoder.begin(/*force_keyframe=*/false);
    t = Clock::now();
    for (std::size_t c = 0; c < encoder.chunk_count(); ++c) encoder.quantize_chunk(c, next);
    const double temporal_ms = ms_since(t);
    for (std::size_t c = 0; c < encoder.chunk_count(); c += kDracoInterleave)
      encoder.encode_chunks(c, std::min(kDracoInterleave, encoder.chunk_count() - c));
    const EncodedFrameSummary s = encoder.finish();
    if (r < 0) continue;  // the warm-up round
    temporal.push_back(temporal_ms * 1e6 / n);
    sent += static_cast<double>(s.present_vertices) / n;
    quantize.push_back(quantize_ms * 1e6 / n);
    ours.push_back(ours_ms * 1e6 / n);
    grouped.push_back(grouped_ms * 1e6 / n);
    dracos.push_back(draco_ms * 1e6 / n);
    bytes += total / n;
  }
  return {bench::median(quantize), bench::median(ours), bench::median(grouped), bench::median(dracos), bytes / rounds,
          bench::median(temporal), sent / rounds};
}

}  // namespace

int main(int argc, char** argv) {
  try {
    const bool quick = argc > 1 && std::string(argv[1]) == "--quick";
    const TriMesh armadillo = repair_mesh(read_mesh(FILIGREE_REPO_DATA_DIR "/armadillo.off"), {}, nullptr);
    struct Case {
      std::string name;
      TriMesh mesh;
    };
    std::vector<Case> cases;
    const auto ordered = [](const TriMesh& m) { return permute_vertices(m, locality_order(m.positions)); };
    cases.push_back({"armadillo (real)", ordered(armadillo)});
    cases.push_back({"armadillo Loop x1", ordered(bench::subdivide(armadillo, 1, 0))});
    if (!quick) cases.push_back({"armadillo Loop x2 + sqrt3", ordered(bench::subdivide(armadillo, 2, 1))});
    std::printf("# Frame encoding, one thread, keyframes (every vertex sent), max error 5e-5 of the diagonal\n\n");
    std::printf("| mesh | vertices | motion | quantize ns/vertex | Draco buffers, ours ns/vertex | ours, %zu chunks interleaved | "
                "Draco's encoder ns/vertex | Draco's / ours | bytes/vertex | next frame: quantize ns/vertex | next frame: "
                "vertices sent |\n|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|\n",
                kDracoInterleave);
    for (const Case& c : cases) {
      for (Motion m : {Motion::kBend, Motion::kTwist}) {
        const Row r = measure(c.mesh, m, quick ? 3 : 5);
        std::printf("| %s | %zu | %s | %.1f | %.1f | %.1f | %.1f | %.2f | %.3f | %.1f | %.1f%% |\n", c.name.c_str(), c.mesh.vertex_count(),
                    to_string(m), r.quantize_ns, r.ours_ns, r.grouped_ns, r.draco_ns, r.draco_ns / r.ours_ns, r.bytes_per_vertex,
                    r.temporal_quantize_ns, 100.0 * r.temporal_sent);
        std::fflush(stdout);
      }
    }
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "filigree_bench_encoder: %s\n", e.what());
    return 1;
  }
}
