#include "bench/service_harness.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <numbers>
#include <sstream>
#include <stdexcept>
#include <thread>

#include <unistd.h>

#include "bench/sample_stats.h"
#include "bench/subdivide.h"
#include "filigree/channel_arguments.h"
#include "mesh/mesh_io.h"
#include "mesh/mesh_validation.h"
#include "mesh/vertex_order.h"
#include "runtime/procedural_motion.h"

namespace filigree::bench {

std::size_t delta_bytes(const v1::Frame& f) {
  std::size_t bytes = f.deltas().size();
  for (const v1::DeltaChunk& c : f.chunks()) bytes += c.deltas().size() + 4 * static_cast<std::size_t>(c.runs_size());
  return bytes;
}

MotionPoses::MotionPoses(const v1::CreateSessionResponse::Created& created) {
  const auto& base = created.info().base();
  for (int i = 0; i + 2 < base.positions_size(); i += 3)
    base_rest_.emplace_back(base.positions(i), base.positions(i + 1), base.positions(i + 2));
  Vec3 lo = base_rest_[0], hi = lo;
  for (const Vec3& p : base_rest_) lo = lo.cwiseMin(p), hi = hi.cwiseMax(p);
  diag_ = (hi - lo).norm();
  for (std::uint32_t i = 0; i < base_rest_.size(); ++i)
    if ((base_rest_[i] - base_rest_[0]).norm() < 0.08 * diag_) bumped_.push_back(i);
}

void MotionPoses::fill(v1::DriveRequest& r, Movement motion, int p) const {
  if (motion == Movement::kWholeBody) {
    const Pose pose = procedural_pose(base_rest_, filigree::Motion::kBend, 0.5 + 0.5 * std::sin(0.2 * p));
    for (const Vec3& v : pose.positions)
      for (int k = 0; k < 3; ++k) r.add_positions(static_cast<float>(v[k]));
  } else {
    const double h = 0.02 * diag_ * std::sin(0.2 * p);
    for (std::uint32_t i : bumped_) {
      const double d = (base_rest_[i] - base_rest_[0]).norm() / (0.08 * diag_);
      const Vec3 v = base_rest_[i] + h * (1.0 - d * d) * Vec3(0.0, 1.0, 0.0);
      r.add_indices(i);
      for (int k = 0; k < 3; ++k) r.add_positions(static_cast<float>(v[k]));
    }
  }
}

std::unique_ptr<grpc::ClientContext> context(const std::string& id, const std::string& token) {
  auto c = std::make_unique<grpc::ClientContext>();
  c->AddMetadata("x-filigree-token", token);
  c->AddMetadata("x-session-id", id);
  return c;
}

Result run(v1::Filigree::Stub& stub, const v1::CreateSessionResponse::Created& created, int watchers, int poses,
           Movement motion, v1::FrameFormat format) {
  const std::string id = created.info().session_id();
  const std::size_t n = created.info().rest().vertex_count();
  const MotionPoses motions(created);

  // Watchers read as fast as they can on their own threads.
  std::vector<std::unique_ptr<grpc::ClientContext>> contexts;
  std::vector<std::thread> threads;
  std::atomic<std::size_t> watcher_frames{0};
  for (int w = 0; w < watchers; ++w) {
    contexts.push_back(context(id, created.viewer_token()));
    threads.emplace_back([&, ctx = contexts.back().get()] {
      v1::WatchRequest wr;
      wr.set_session_id(id);
      wr.set_frame_format(format);
      auto reader = stub.Watch(ctx, wr);
      v1::Frame f;
      while (reader->Read(&f)) ++watcher_frames;
      reader->Finish();
    });
  }

  auto ctx = context(id, created.editor_token());
  auto drive = stub.Drive(ctx.get());
  std::vector<double> latency, compute, encode, both, other;
  double first_ms = 0.0;
  double bytes = 0.0, worst_error = 0.0, present = 0.0;
  auto start = Clock::now();
  for (int p = 1; p <= kWarmupFrames + poses; ++p) {
    if (p == kWarmupFrames + 1) start = Clock::now();
    v1::DriveRequest r;
    r.set_session_id(id);
    r.set_pose_id(static_cast<std::uint64_t>(p));
    r.set_frame_format(format);
    motions.fill(r, motion, p);
    const auto sent = Clock::now();
    drive->Write(r);
    v1::Frame f;
    do {
      if (!drive->Read(&f)) return {};
    } while (f.pose_id() != static_cast<std::uint64_t>(p));
    const double ms = std::chrono::duration<double, std::milli>(Clock::now() - sent).count();
    worst_error = std::max(worst_error, static_cast<double>(f.max_error()));  // every frame keeps the promise
    if (p == 1) first_ms = ms;
    if (p <= kWarmupFrames) continue;
    latency.push_back(ms);
    compute.push_back(f.stats().compute_ms());
    encode.push_back(f.stats().encode_ms());
    both.push_back(f.stats().compute_ms() + f.stats().encode_ms());
    other.push_back(latency.back() - both.back());
    bytes += static_cast<double>(delta_bytes(f));
    present += f.stats().present_vertices() ? f.stats().present_vertices() : static_cast<double>(n);
  }
  const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
  drive->WritesDone();
  v1::Frame f;
  while (drive->Read(&f)) {
  }
  drive->Finish();
  for (auto& c : contexts) c->TryCancel();
  for (auto& t : threads) t.join();

  Result out;
  out.first = first_ms;
  out.p50 = percentile(latency, 0.5);
  out.p99 = percentile(latency, 0.99);
  out.compute_p50 = percentile(compute, 0.5);
  out.compute_p99 = percentile(compute, 0.99);
  out.encode_p50 = percentile(encode, 0.5);
  out.both_p99 = percentile(both, 0.99);
  out.other_p50 = percentile(other, 0.5);
  out.present = present / poses / static_cast<double>(n);
  out.fps = poses / seconds;
  out.bytes_per_vertex = bytes / poses / static_cast<double>(n);
  // Relative to the rest mesh's diagonal, as the server's error target is.
  const auto& rest = created.info().rest().positions();
  Vec3 rlo = Vec3::Constant(std::numeric_limits<double>::infinity()), rhi = -rlo;
  for (int i = 0; i + 2 < rest.size(); i += 3) {
    const Vec3 p(rest[i], rest[i + 1], rest[i + 2]);
    rlo = rlo.cwiseMin(p), rhi = rhi.cwiseMax(p);
  }
  out.max_error_rel = worst_error / (rhi - rlo).norm();
  out.watcher_frames = watcher_frames;
  return out;
}

std::string obj_bytes(const TriMesh& mesh) {
  const auto path = std::filesystem::temp_directory_path() / ("filigree_bench_" + std::to_string(::getpid()) + ".obj");
  write_mesh(mesh, path);
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  std::filesystem::remove(path);
  return s.str();
}

std::string ply_bytes(const TriMesh& mesh) {
  std::string out = "ply\nformat binary_little_endian 1.0\nelement vertex " + std::to_string(mesh.vertex_count()) +
                    "\nproperty float x\nproperty float y\nproperty float z\nelement face " +
                    std::to_string(mesh.face_count()) + "\nproperty list uchar uint vertex_indices\nend_header\n";
  const std::size_t header = out.size();
  out.resize(header + 12 * mesh.vertex_count() + 13 * mesh.face_count());
  char* at = out.data() + header;  // little-endian, as this machine is
  for (const Vec3& p : mesh.positions)
    for (int k = 0; k < 3; ++k) {
      const float c = static_cast<float>(p[k]);
      std::memcpy(at, &c, 4), at += 4;
    }
  for (const Triangle& f : mesh.faces) {
    *at++ = 3;
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t i = f[k];
      std::memcpy(at, &i, 4), at += 4;
    }
  }
  return out;
}

namespace {
// A /proc/PID/status field in kB ("VmRSS", "VmHWM"), in bytes.
double status_bytes(int pid, const std::string& field) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind(field + ":", 0) == 0) return 1024.0 * std::stod(line.substr(field.size() + 1));
  return 0.0;
}
}  // namespace

double resident_bytes(int pid) { return status_bytes(pid, "VmRSS"); }

double peak_resident_bytes(int pid) { return status_bytes(pid, "VmHWM"); }

v1::CreateSessionResponse::Created upload(v1::Filigree::Stub& stub, const std::string& bytes) {
  grpc::ClientContext ctx;
  auto up = stub.CreateSession(&ctx);
  v1::CreateSessionRequest begin;
  begin.mutable_begin()->set_format("obj");
  begin.mutable_begin()->set_total_bytes(bytes.size());
  up->Write(begin);
  for (std::size_t at = 0; at < bytes.size(); at += 1 << 20) {
    v1::CreateSessionRequest chunk;
    chunk.set_chunk(bytes.substr(at, 1 << 20));
    up->Write(chunk);
  }
  up->WritesDone();
  v1::CreateSessionResponse r;
  v1::CreateSessionResponse::Created created;
  while (up->Read(&r))
    if (r.has_created()) created = r.created();
  const grpc::Status status = up->Finish();
  if (!status.ok()) throw std::runtime_error("upload failed: " + status.error_message());
  return created;
}

namespace {
std::vector<std::string> server_args(const std::filesystem::path& data, const std::vector<std::string>& extra,
                                     bool default_limits) {
  std::vector<std::string> args{"--data-dir", data.string()};
  if (!default_limits) args.insert(args.end(), {"--max-message-mib", "256"});
  args.insert(args.end(), extra.begin(), extra.end());
  return args;
}
}  // namespace

BenchServer::BenchServer(const std::string& binary, const std::string& tag, const std::vector<std::string>& extra,
                         bool default_limits)
    : data(std::filesystem::temp_directory_path() / ("filigree_bench_" + tag + "_" + std::to_string(::getpid()))),
      server(binary, server_args(data, extra, default_limits)),
      stub(v1::Filigree::NewStub(
          grpc::CreateCustomChannel(server.address(), grpc::InsecureChannelCredentials(), filigree::frame_channel_arguments()))) {}

BenchServer::~BenchServer() {
  server.terminate();
  std::error_code ignored;  // a destructor must not throw
  std::filesystem::remove_all(data, ignored);
}

Case bench_mesh(const std::string& size) {
  const std::string repo = FILIGREE_REPO_DATA_DIR, shared = FILIGREE_SHARED_DATA_DIR;
  const bool have_shared = std::filesystem::exists(shared + "/camel.off") && std::filesystem::exists(shared + "/bunny.off");
  RepairReport report;
  const auto load = [&](const std::string& path) { return repair_mesh(read_mesh(path), {}, &report); };
  if (size == "small")
    return have_shared ? Case{"camel (real, 9.8k)", load(shared + "/camel.off")} : Case{"armadillo (real, 26k)", load(repo + "/armadillo.off")};
  if (size == "medium")
    return have_shared ? Case{"bunny Loop x1", bench::subdivide(load(shared + "/bunny.off"), 1, 0)}
                       : Case{"armadillo Loop x1 (104k)", bench::subdivide(load(repo + "/armadillo.off"), 1, 0)};
  if (size == "large") {
    const TriMesh large = bench::subdivide(load(repo + "/armadillo.off"), 2, 1);
    return {"armadillo Loop x2 + sqrt3", permute_vertices(large, locality_order(large.positions))};
  }
  if (size == "huge") return {"bumpy UV sphere (2M)", bumpy_uv_sphere(1000, 2000)};
  throw std::invalid_argument("--mesh must be small, medium, large or huge, got " + size);
}

TriMesh bumpy_uv_sphere(int rings, int segments) {
  const auto point = [](double theta, double phi) {
    const double r = 1.0 + 0.05 * std::sin(5 * theta) * std::cos(4 * phi) + 0.01 * std::sin(40 * theta) * std::sin(40 * phi);
    return Vec3(1.5 * r * std::sin(theta) * std::cos(phi), r * std::sin(theta) * std::sin(phi), r * std::cos(theta));
  };
  TriMesh m;
  const auto n = static_cast<Index>(segments);
  m.positions.reserve(2 + static_cast<std::size_t>(rings) * n);
  m.positions.push_back(point(0.0, 0.0));  // north pole: vertex 0
  for (int i = 1; i <= rings; ++i)
    for (int j = 0; j < segments; ++j)
      m.positions.push_back(point(std::numbers::pi * i / (rings + 1), 2 * std::numbers::pi * j / segments));
  const Index south = static_cast<Index>(m.positions.size());
  m.positions.push_back(point(std::numbers::pi, 0.0));
  const auto at = [&](int ring, Index j) { return 1 + static_cast<Index>(ring - 1) * n + j % n; };  // ring 1 … rings
  m.faces.reserve(2 * static_cast<std::size_t>(rings) * n);
  for (Index j = 0; j < n; ++j) m.faces.push_back({0, at(1, j), at(1, j + 1)});
  for (int i = 1; i < rings; ++i)
    for (Index j = 0; j < n; ++j) {
      m.faces.push_back({at(i, j), at(i + 1, j), at(i + 1, j + 1)});
      m.faces.push_back({at(i, j), at(i + 1, j + 1), at(i, j + 1)});
    }
  for (Index j = 0; j < n; ++j) m.faces.push_back({south, at(rings, j + 1), at(rings, j)});
  return m;
}

}  // namespace filigree::bench
