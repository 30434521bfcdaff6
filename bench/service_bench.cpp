// End-to-end service benchmark on loopback (issues 4 and 11): pose → frame
// latency p50/p99, compute and encode p50 and frames per second for a driver,
// bytes per vertex per frame and the stated max error, for a whole-body motion
// and a local one (a bump on the base, sent as partial poses), on a ≈10k real,
// a ≈150k and a ≥ 1M mesh; then 8 and 16 sessions driven at once, with
// their aggregate rate and the slowest session's share.
// Targets (issue 11): encode p50 ≤ 0.5 × compute p50; pose → frame p50 ≤ 40 ms
// at ≥ 1M vertices, p99 ≤ 1.5 × compute + encode; local motion ≤ 0.25 B/vertex,
// whole-body ≤ 2 B/vertex at ≤ 5e-5 of the diagonal; 8 sessions: no session
// below 0.7 × the mean rate.
//
// The driver sends a pose, waits for the frame that answers it, then sends the
// next (closed loop), so latency is not inflated by queueing. The first
// kWarmupFrames frames of each drive (its stream's set-up, the first
// keyframe) are timed apart, as "first frame ms"; percentiles, rates and
// sizes are over the frames after them (600, or 60 on a ≥ 1M mesh: a p99 of
// 120 frames, as before, was the second-worst frame, often the first one). "other" is the
// median over frames of pose → frame minus the frame's compute and encode:
// carrying the pose and the frame (gRPC, serialisation, loopback), waiting
// for a worker, and publishing.
//
// Usage: filigree_bench_service [server-binary] [--format single|chunked]
//        [--quick] (the quick run skips the ≥ 1M mesh and the 16 sessions)
//        [--large] (only the ≥ 1M mesh's single-watcher drives: for profiling)
//        [--single-stall] (a small session driven while two clients poll
//        GetState in the single-buffer format on a driven 435k session: each
//        new frame is transcoded into one buffer, off gRPC's callback threads)
//        [--against OTHER-SERVER [--rounds N] [--mesh small|medium|large|huge]]
//        (before/after: both servers, one mesh, the single-watcher whole-body
//        drive alternating between them N times, so that a drift of the
//        machine's speed falls on both; prints each round and the medians)
//        [--huge [--poses N]] (only: the ≥ 2M-vertex mesh from upload to
//        first frame with the C++ client library, on a server with its
//        default limits; then N closed-loop poses, 40 by default.
//        bench/service_large_mesh.py is the same with the Python package)

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <stdexcept>
#include <thread>
#include <vector>
#include <atomic>

#include <grpcpp/grpcpp.h>

#include "bench/sample_stats.h"
#include "bench/service_harness.h"
#include "bench/subdivide.h"
#include "filigree/client.h"
#include "filigree/v1/filigree.grpc.pb.h"
#include "mesh/mesh_io.h"
#include "mesh/mesh_validation.h"
#include "runtime/procedural_motion.h"
#include "support/server_process.h"

namespace {

using namespace filigree;
using namespace filigree::bench;

v1::FrameFormat g_format = v1::FRAME_FORMAT_CHUNKED;

// 8 or 16 sessions of one mesh, each driven closed-loop (whole-body) on its
// own thread for `seconds`: frames per session.
std::vector<double> run_many(v1::Filigree::Stub& stub, const std::string& bytes, int sessions, double seconds) {
  std::vector<v1::CreateSessionResponse::Created> created;
  for (int i = 0; i < sessions; ++i) created.push_back(upload(stub, bytes));
  std::vector<double> fps(static_cast<std::size_t>(sessions));
  std::vector<std::thread> threads;
  for (int i = 0; i < sessions; ++i)
    threads.emplace_back([&, i] {
      const auto& c = created[static_cast<std::size_t>(i)];
      const auto& base = c.info().base();
      std::vector<Vec3> base_rest;
      for (int k = 0; k + 2 < base.positions_size(); k += 3)
        base_rest.emplace_back(base.positions(k), base.positions(k + 1), base.positions(k + 2));
      auto ctx = context(c.info().session_id(), c.editor_token());
      auto drive = stub.Drive(ctx.get());
      const auto start = Clock::now();
      int frames = 0;
      for (int p = 1; std::chrono::duration<double>(Clock::now() - start).count() < seconds; ++p) {
        const Pose pose = procedural_pose(base_rest, filigree::Motion::kBend, 0.5 + 0.5 * std::sin(0.2 * p + i));
        v1::DriveRequest r;
        r.set_session_id(c.info().session_id());
        r.set_pose_id(static_cast<std::uint64_t>(p));
        r.set_frame_format(g_format);
        for (const Vec3& v : pose.positions)
          for (int k = 0; k < 3; ++k) r.add_positions(static_cast<float>(v[k]));
        drive->Write(r);
        v1::Frame f;
        do {
          if (!drive->Read(&f)) return;
        } while (f.pose_id() != static_cast<std::uint64_t>(p));
        ++frames;
      }
      fps[static_cast<std::size_t>(i)] = frames / std::chrono::duration<double>(Clock::now() - start).count();
      drive->WritesDone();
      v1::Frame f;
      while (drive->Read(&f)) {
      }
      drive->Finish();
    });
  for (auto& t : threads) t.join();
  for (const auto& c : created) {
    grpc::ClientContext ctx;
    ctx.AddMetadata("x-filigree-token", c.editor_token());
    ctx.AddMetadata("x-session-id", c.info().session_id());
    v1::CloseSessionRequest r;
    r.set_session_id(c.info().session_id());
    v1::CloseSessionResponse out;
    stub.CloseSession(&ctx, r, &out);
  }
  return fps;
}

// --against: `a` and `b` alternate on one mesh, `rounds` times each (one
// server idle while the other is driven), and print each round and the
// medians of both with b's over a's.
int compare_servers(const std::string& a, const std::string& b, const std::string& which, int rounds) {
  const TriMesh mesh = bench_mesh(which).mesh;
  const std::string bytes = obj_bytes(mesh);
  const int poses = mesh.vertex_count() > 500000 ? 60 : 300;
  struct Side {
    std::string binary;
    std::unique_ptr<BenchServer> server;
    v1::CreateSessionResponse::Created created;
    std::vector<double> encode, compute, ratio, p50;
  };
  std::array<Side, 2> sides;
  for (int k = 0; k < 2; ++k) {
    Side& s = sides[static_cast<std::size_t>(k)];
    s.binary = k == 0 ? a : b;
    s.server = std::make_unique<BenchServer>(s.binary, "ab_" + std::to_string(k));
    s.created = upload(*s.server->stub, bytes);
  }
  std::printf("# Before/after: %zu vertices, whole body, 1 watcher, %d poses a round\n\n"
              "| round | server | compute p50 ms | encode p50 ms | encode / compute | p50 ms |\n|---:|---|---:|---:|---:|---:|\n",
              mesh.vertex_count(), poses);
  for (int r = 0; r < rounds; ++r)
    for (int i = 0; i < 2; ++i) {
      // Each round starts with the other server, so neither always runs first.
      Side& s = sides[static_cast<std::size_t>((r + i) % 2)];
      const Result res = run(*s.server->stub, s.created, 1, poses, Movement::kWholeBody, g_format);
      s.encode.push_back(res.encode_p50), s.compute.push_back(res.compute_p50), s.p50.push_back(res.p50);
      s.ratio.push_back(res.encode_p50 / res.compute_p50);
      std::printf("| %d | %s | %.3f | %.3f | %.3f | %.3f |\n", r + 1, (r + i) % 2 == 0 ? "a" : "b", res.compute_p50, res.encode_p50,
                  s.ratio.back(), res.p50);
      std::fflush(stdout);
    }
  std::printf("\n| medians | compute p50 ms | encode p50 ms | encode / compute | p50 ms |\n|---|---:|---:|---:|---:|\n");
  for (int k = 0; k < 2; ++k) {
    Side& s = sides[static_cast<std::size_t>(k)];
    std::printf("| %s: %s | %.3f | %.3f | %.3f | %.3f |\n", k == 0 ? "a" : "b", s.binary.c_str(), percentile(s.compute, 0.5),
                percentile(s.encode, 0.5), percentile(s.ratio, 0.5), percentile(s.p50, 0.5));
  }
  const auto over = [&](std::vector<double> Side::*v) { return percentile(sides[1].*v, 0.5) / percentile(sides[0].*v, 0.5); };
  std::printf("| b / a | %.3f | %.3f | %.3f | %.3f |\n", over(&Side::compute), over(&Side::encode), over(&Side::ratio), over(&Side::p50));
  return 0;
}

// --single-stall: the small session's frame intervals, closed loop, while
// a 435k session (the dragon when ../shared has it, else the Armadillo
// subdivided twice, 416k) is driven and two clients poll GetState in the
// default (single-buffer) format, so that nearly every call transcodes a
// new frame. Prints the intervals' p50, p99 and longest, and the calls made.
int single_stall(const std::string& server_binary) {
  BenchServer bench_server(server_binary, "single");
  v1::Filigree::Stub* const stub = bench_server.stub.get();
  RepairReport report;
  const std::string dragon = std::string(FILIGREE_SHARED_DATA_DIR) + "/dragon.ply";
  const TriMesh armadillo = repair_mesh(read_mesh(std::string(FILIGREE_REPO_DATA_DIR) + "/armadillo.off"), {}, &report);
  const TriMesh large = std::filesystem::exists(dragon) ? repair_mesh(read_mesh(dragon), {}, &report) : bench::subdivide(armadillo, 2, 0);
  const auto big = upload(*stub, obj_bytes(large));
  const auto small = upload(*stub, obj_bytes(armadillo));
  std::atomic<bool> stop{false};
  std::atomic<int> calls{0};
  std::vector<std::thread> load;
  load.emplace_back([&] {
    while (!stop) run(*stub, big, 0, 20, Movement::kWholeBody, g_format);
  });
  for (int k = 0; k < 2; ++k)
    load.emplace_back([&] {
      v1::GetStateRequest r;
      r.set_session_id(big.info().session_id());  // frame_format: the default, FRAME_FORMAT_SINGLE
      while (!stop) {
        v1::SessionState state;
        if (stub->GetState(context(r.session_id(), big.viewer_token()).get(), r, &state).ok()) ++calls;
      }
    });
  std::this_thread::sleep_for(std::chrono::seconds(2));  // the load's steady state
  const std::string id = small.info().session_id();
  auto ctx = context(id, small.editor_token());
  auto drive = stub->Drive(ctx.get());
  std::vector<double> intervals;
  const auto start = Clock::now();
  auto last = start;
  for (std::uint64_t p = 1; std::chrono::duration<double>(Clock::now() - start).count() < 6.0; ++p) {
    v1::DriveRequest r;  // base vertex 0 nudged: a partial pose
    r.set_session_id(id);
    r.set_pose_id(p);
    r.add_indices(0);
    for (const float c : {0.001f * static_cast<float>(p % 10), 0.0f, 0.0f}) r.add_positions(c);
    drive->Write(r);
    v1::Frame f;
    do {
      if (!drive->Read(&f)) throw std::runtime_error("the small session's drive ended");
    } while (f.pose_id() != p);
    const auto now = Clock::now();
    intervals.push_back(std::chrono::duration<double, std::milli>(now - last).count());
    last = now;
  }
  drive->WritesDone();
  for (v1::Frame f; drive->Read(&f);) {
  }
  drive->Finish();
  stop = true;
  for (auto& t : load) t.join();
  std::printf("# Single-buffer GetState polled on a driven %zu-vertex session\n\nsmall session (%zu vertices), 6 s closed loop: "
              "%zu frames, interval p50 %.2f ms, p99 %.1f ms, longest %.1f ms; %d GetState calls answered\n",
              large.vertex_count(), armadillo.vertex_count(), intervals.size(), percentile(intervals, 0.5), percentile(intervals, 0.99),
              *std::max_element(intervals.begin(), intervals.end()), calls.load());
  return 0;
}

// --huge: the ≥ 2M-vertex mesh (bench_mesh("huge")) as a user meets it.
// A server of its own with its default limits (the rest mesh, ~66 MB, is
// over half its 64 MiB messages: it comes in GetRestMesh parts); the upload
// as binary PLY through filigree::Client::create_session, which returns
// with the tokens and the rest mesh (as the Python package's does); a Drive
// stream and a FrameDecoder; the first pose, then `poses` closed loop (the
// whole-body bend): each timed from send to its frame decoded. A join
// afterwards times reading the rest mesh alone: upload → tokens is about
// upload → session less it. Server memory: its peak (VmHWM) and now (VmRSS).
int huge_end_to_end(const std::string& server_binary, int poses) {
  const auto secs = [](Clock::time_point a, Clock::time_point b) { return std::chrono::duration<double>(b - a).count(); };
  const Case c = bench_mesh("huge");
  const std::string bytes = ply_bytes(c.mesh);
  BenchServer bench_server(server_binary, "huge", {}, /*default_limits=*/true);
  filigree::Client client(bench_server.server.address());
  std::map<std::string, Clock::time_point> first;  // when each stage was first reported
  const auto start = Clock::now();
  const SessionHandle session =
      client.create_session(bytes, "ply", {}, "filigree_bench_service", [&](const std::string& stage, double fraction) {
        if (stage == "uploading" && fraction < 1.0) return;  // "uploading" when the last byte went
        first.try_emplace(stage, Clock::now());
      });
  const auto made = Clock::now();

  std::vector<Vec3> base_rest;
  for (std::size_t i = 0; i + 2 < session.mesh.base_positions.size(); i += 3)
    base_rest.emplace_back(session.mesh.base_positions[i], session.mesh.base_positions[i + 1], session.mesh.base_positions[i + 2]);
  FrameDecoder decoder(session.mesh.rest_positions);
  auto driver = client.drive(session.session_id, session.editor_token, "filigree_bench_service");
  // Sends pose p (the bend at its phase) and decodes the frame that includes it.
  const auto pose_to_frame = [&](std::uint64_t p) {
    const Pose pose = procedural_pose(base_rest, filigree::Motion::kBend, 0.5 + 0.5 * std::sin(0.2 * static_cast<double>(p)));
    std::vector<float> flat;
    flat.reserve(3 * pose.positions.size());
    for (const Vec3& v : pose.positions) flat.insert(flat.end(), {float(v.x()), float(v.y()), float(v.z())});
    if (!driver->send(p, flat)) throw std::runtime_error("the drive ended: " + driver->finish().error_message());
    for (;;) {
      const std::optional<v1::Frame> f = driver->read();
      if (!f) throw std::runtime_error("the drive ended: " + driver->finish().error_message());
      if (f->has_level()) continue;
      const DecodedFrame d = decoder.decode(*f);
      if (d.pose_id >= p) return d.vertex_count();
    }
  };
  if (pose_to_frame(1) != session.mesh.vertex_count()) throw std::runtime_error("the first frame is not the whole mesh");
  const auto first_frame = Clock::now();
  std::vector<double> latency;
  for (int p = 2; p <= poses + 1; ++p) {
    const auto sent = Clock::now();
    pose_to_frame(static_cast<std::uint64_t>(p));
    latency.push_back(1e3 * secs(sent, Clock::now()));
  }
  driver->writes_done();
  driver->finish();
  const auto join_start = Clock::now();
  const SessionMesh joined = client.join(session.session_id, session.viewer_token);
  const double join_seconds = secs(join_start, Clock::now());
  const int pid = bench_server.server.pid();

  const auto at = [&](const std::string& stage) { return first.contains(stage) ? secs(start, first[stage]) : -1.0; };
  std::printf("# A %zu-vertex session end to end (C++ client library), %zu faces, default server limits\n\n",
              c.mesh.vertex_count(), c.mesh.face_count());
  std::printf("Stages from the start of the upload (s): last byte sent %.2f, validating %.2f, simplifying %.2f, "
              "starting %.2f; session (tokens and rest mesh) %.2f; rest mesh read again by a join: %.2f s (%zu vertices)\n\n",
              at("uploading"), at("validating"), at("simplifying"), at("starting"), secs(start, made), join_seconds,
              joined.vertex_count());
  std::printf("| client | vertices | upload MB | upload → session s | session → first frame s | upload → first frame s | "
              "frame p50 ms | frame p99 ms | poses | server peak RSS MiB | server RSS after MiB |\n"
              "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
  std::printf("| C++ | %zu | %.1f | %.2f | %.2f | %.2f | %.1f | %.1f | %d | %.0f | %.0f |\n", session.mesh.vertex_count(),
              bytes.size() / 1e6, secs(start, made), secs(made, first_frame), secs(start, first_frame), percentile(latency, 0.5),
              percentile(latency, 0.99), poses, peak_resident_bytes(pid) / (1 << 20), resident_bytes(pid) / (1 << 20));
  return 0;
}

int main_impl(int argc, char** argv) {
  std::string server_binary = FILIGREE_SERVER_BINARY;
  bool quick = false, large_only = false;
  std::string against, which = "medium";
  bool single_stall_only = false, huge = false;
  int rounds = 5, poses = 40;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--single-stall") {
      single_stall_only = true;
    } else if (a == "--against" && i + 1 < argc) {
      against = argv[++i];
    } else if (a == "--rounds" && i + 1 < argc) {
      rounds = std::max(1, std::stoi(argv[++i]));
    } else if (a == "--mesh" && i + 1 < argc) {
      which = argv[++i];
    } else if (a == "--format" && i + 1 < argc) {
      g_format = std::string(argv[++i]) == "single" ? v1::FRAME_FORMAT_SINGLE : v1::FRAME_FORMAT_CHUNKED;
    } else if (a == "--quick") {
      quick = true;
    } else if (a == "--large") {
      large_only = true;
    } else if (a == "--huge") {
      huge = true;
    } else if (a == "--poses" && i + 1 < argc) {
      poses = std::max(1, std::stoi(argv[++i]));
    } else {
      server_binary = a;
    }
  }
  if (!against.empty()) return compare_servers(server_binary, against, which, rounds);
  if (single_stall_only) return single_stall(server_binary);
  if (huge) return huge_end_to_end(server_binary, poses);
  BenchServer bench_server(server_binary, "data");
  const test::ServerProcess& server = bench_server.server;
  v1::Filigree::Stub* const stub = bench_server.stub.get();

  std::vector<Case> cases;
  if (!large_only) cases.push_back(bench_mesh("small")), cases.push_back(bench_mesh("medium"));
  if (!quick) cases.push_back(bench_mesh("large"));
  std::printf("# Filigree service benchmark (%s frames)\n\n", g_format == v1::FRAME_FORMAT_SINGLE ? "single-buffer" : "chunked");
  std::printf("| mesh | vertices | motion | watchers | first frame ms | p50 ms | p99 ms | compute p50 ms | encode p50 ms | other p50 ms | encode / compute | "
              "p99 / (compute+encode) p99 | frames/s | bytes/vertex/frame | vertices sent | max error / diag | watcher frames |\n");
  std::printf("|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
  struct Memory {
    std::string name;
    std::size_t vertices;
    double first, further;  // bytes per vertex the first session, and each further one, added
  };
  std::vector<Memory> memory;
  std::string many_bytes;  // the ≈150k mesh, for the many-sessions run
  for (const Case& c : cases) {
    const std::string bytes = obj_bytes(c.mesh);
    if (many_bytes.empty() && c.mesh.vertex_count() > 50000) many_bytes = bytes;
    const double empty = resident_bytes(server.pid());
    const v1::CreateSessionResponse::Created created = upload(*stub, bytes);
    const int poses = c.mesh.vertex_count() > 500000 ? 60 : 600;
    struct Run {
      Movement motion;
      int watchers;
    };
    for (const Run r : {Run{Movement::kWholeBody, 1}, Run{Movement::kWholeBody, 8}, Run{Movement::kLocal, 1}}) {
      if (large_only && r.watchers > 1) continue;
      const Result res = run(*stub, created, r.watchers, poses, r.motion, g_format);
      std::printf("| %s | %zu | %s | %d | %.2f | %.2f | %.2f | %.2f | %.2f | %.2f | %.2f | %.2f | %.1f | %.3f | %.1f%% | %.2e | %zu |\n",
                  c.name.c_str(), c.mesh.vertex_count(), r.motion == Movement::kWholeBody ? "whole body" : "local bump",
                  r.watchers, res.first, res.p50, res.p99, res.compute_p50, res.encode_p50, res.other_p50, res.encode_p50 / res.compute_p50,
                  res.p99 / res.both_p99, res.fps, res.bytes_per_vertex, 100.0 * res.present, res.max_error_rel,
                  res.watcher_frames);
      std::fflush(stdout);
    }
    // Further sessions of the now cached mesh, each driven a few frames:
    // what a session holds of its own (issue 10: ≤ 64 bytes per vertex).
    const double one = resident_bytes(server.pid());
    constexpr int kFurther = 3;
    for (int i = 0; i < kFurther; ++i) run(*stub, upload(*stub, bytes), 0, 5, Movement::kWholeBody, g_format);
    const double n = static_cast<double>(c.mesh.vertex_count());
    memory.push_back({c.name, c.mesh.vertex_count(), (one - empty) / n, (resident_bytes(server.pid()) - one) / kFurther / n});
  }
  std::printf("\nServer resident memory (VmRSS), bytes per vertex: the first session of a mesh (hierarchy, model, its own "
              "state, after its three drives) and each further session of the same mesh (its own state, after %d frames).\n\n"
              "| mesh | vertices | first session | each further session |\n|---|---:|---:|---:|\n",
              kWarmupFrames + 5);
  for (const Memory& m : memory) std::printf("| %s | %zu | %.0f | %.0f |\n", m.name.c_str(), m.vertices, m.first, m.further);

  if (large_only) return 0;
  // Many sessions of the ≈150k mesh sharing the machine's cores.
  const double n_many = static_cast<double>(cases[1].mesh.vertex_count());
  std::printf("\nMany sessions of %s (%.0f vertices), each driven closed-loop with the whole-body motion for 10 s.\n\n"
              "| sessions | aggregate frames/s | aggregate vertices/s | mean frames/s per session | slowest | slowest / mean |\n"
              "|---:|---:|---:|---:|---:|---:|\n",
              cases[1].name.c_str(), n_many);
  for (int sessions : quick ? std::vector<int>{8} : std::vector<int>{8, 16}) {
    const std::vector<double> fps = run_many(*stub, many_bytes, sessions, 10.0);
    double total = 0.0, slowest = fps.empty() ? 0.0 : fps[0];
    for (double f : fps) total += f, slowest = std::min(slowest, f);
    const double mean = total / static_cast<double>(fps.size());
    std::printf("| %d | %.1f | %.2e | %.2f | %.2f | %.2f |\n", sessions, total, total * n_many, mean, slowest, slowest / mean);
    std::fflush(stdout);
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return main_impl(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "filigree_bench_service: %s\n", e.what());
    return 1;
  }
}
