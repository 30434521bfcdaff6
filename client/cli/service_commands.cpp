// `filigree upload`, `drive`, `watch`, `sessions`: the CLI as a client of
// filigree-server (through the client library, filigree::client).

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <condition_variable>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <CLI/CLI.hpp>

#include "cli/channel_security.h"
#include "cli/progress_bar.h"
#include "cli/rest_mesh.h"
#include "cli/session_token.h"
#include "filigree/client.h"
#include "mesh/gltf_io.h"
#include "mesh/mesh_io.h"
#include "runtime/pose_io.h"
#include "runtime/procedural_motion.h"

namespace filigree::cli {
namespace {

using Clock = std::chrono::steady_clock;
constexpr const char* kDefaultServer = "127.0.0.1:50051";

struct UploadArgs {
  std::string mesh, server = kDefaultServer, name = "filigree-cli";
  unsigned base_vertices = 0, bits = 0;
  double threshold = 0.0;
  bool whole_mesh = false;
  std::string skinning = "linear";
};

struct SessionArgs {
  std::string session, token_file, server = kDefaultServer, output;
  int frames = 0;
};

struct DriveArgs : SessionArgs {
  std::string motion, name = "filigree-cli";
  std::vector<std::string> poses;
  double rate = 60.0;
};

struct PlayArgs : SessionArgs {
  std::string clip, name = "filigree-cli";
  double speed = 1.0, fps = 30.0, start = 0.0;
  bool loop = false;
};

struct WatchArgs : SessionArgs {
  std::uint64_t after = 0;
  double fps = 30.0;
  std::uint32_t max_vertices = 0;  // a level of detail; 0: full detail
};

std::string read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error("cannot read " + path);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// The session token: from --token-file, else $FILIGREE_TOKEN. Never an
// argument: a command line is visible to every user of the machine (ps).
std::string session_token(const SessionArgs& a) { return read_session_token(a.token_file, "--token-file", "FILIGREE_TOKEN"); }

std::string format_of(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  if (!ext.empty()) ext.erase(0, 1);
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

std::vector<float> to_floats(const std::vector<Vec3>& v) {
  std::vector<float> out(3 * v.size());
  for (std::size_t i = 0; i < v.size(); ++i)
    for (int c = 0; c < 3; ++c) out[3 * i + c] = static_cast<float>(v[i][c]);
  return out;
}

// The rest mesh of the level frames are at: the level's vertices (in its
// order) and faces; the session's rest mesh at full detail.
TriMesh level_rest_mesh(const SessionMesh& session, const DecodedLevel* level) {
  if (level == nullptr || level->full_detail) return rest_mesh(session);
  TriMesh mesh;
  mesh.positions = points_from_xyz(level->rest_positions);
  mesh.faces.resize(level->faces.size() / 3);
  for (std::size_t f = 0; f < mesh.faces.size(); ++f)
    mesh.faces[f] = {level->faces[3 * f], level->faces[3 * f + 1], level->faces[3 * f + 2]};
  return mesh;
}

// .glb: every frame as a morph-target animation of `mesh` (their rest
// mesh); any other format: the last frame.
void write_frames(TriMesh mesh, const std::vector<std::vector<Vec3>>& frames, double fps, const std::string& path) {
  if (frames.empty()) throw std::runtime_error("no frames received: nothing to write to " + path);
  if (format_of(path) == "glb") {
    write_glb_animation(mesh, frames, fps, path);
    std::fprintf(stderr, "wrote %s: %zu frames of %zu vertices\n", path.c_str(), frames.size(), mesh.vertex_count());
  } else {
    mesh.positions = frames.back();
    write_mesh(mesh, path);
    std::fprintf(stderr, "wrote %s: the last of %zu frames\n", path.c_str(), frames.size());
  }
}

void write_frames(const SessionMesh& session, const std::vector<std::vector<Vec3>>& frames, double fps,
                  const std::string& path) {
  write_frames(rest_mesh(session), frames, fps, path);
}

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(std::lround(p * static_cast<double>(v.size() - 1)))];
}

// ---------------------------------------------------------------- upload

void upload(const UploadArgs& a) {
  v1::SessionOptions options;
  options.set_base_vertices(a.base_vertices);
  options.set_threshold(a.threshold);
  if (a.skinning == "dual-quaternion") {
    options.set_skinning(v1::SKINNING_DUAL_QUATERNION);
  } else if (a.skinning != "linear") {
    throw std::invalid_argument("--skinning takes linear or dual-quaternion, not '" + a.skinning + "'");
  }
  options.set_whole_mesh(a.whole_mesh);
  options.set_quantization_bits(a.bits);
  const std::string bytes = read_file(a.mesh);

  Client client(a.server, channel_credentials());
  client.set_api_key(api_key());
  std::string stage;
  std::unique_ptr<ProgressBar> bar;  // one bar per stage
  const SessionHandle s = client.create_session(bytes, format_of(a.mesh), options, a.name,
                                                [&](const std::string& next, double fraction) {
                                                  if (next != stage || !bar) {
                                                    bar = std::make_unique<ProgressBar>(next);
                                                    stage = next;
                                                  }
                                                  bar->update(fraction);
                                                });
  bar.reset();
  std::printf("session_id: %s\neditor_token: %s\nviewer_token: %s\n", s.session_id.c_str(), s.editor_token.c_str(),
              s.viewer_token.c_str());
  std::printf("cached: %s\nvertices: %zu\nbase_vertices: %zu\n", s.cached ? "yes" : "no", s.mesh.vertex_count(),
              s.mesh.base_vertex_count());
  if (s.mesh.skeleton.joints_size() > 0) {
    std::printf("joints: %d\nclips:", s.mesh.skeleton.joints_size());
    for (const auto& c : s.mesh.skeleton.clips()) std::printf(" %s (%.2f s)", c.name().c_str(), c.duration_seconds());
    std::printf("\n");
  }
}

// ---------------------------------------------------------------- drive

// The poses to send, in base order as floats: a procedural motion run back
// and forth over `frames` poses, or pose files cycled.
std::vector<std::vector<float>> make_poses(const DriveArgs& a, const SessionMesh& session) {
  std::vector<std::vector<float>> out;
  if (!a.motion.empty()) {
    const auto motion = parse_motion(a.motion);
    if (!motion) throw std::invalid_argument("--motion takes bend, twist, twist360, wave, bump or fold, not '" + a.motion + "'");
    const std::vector<Vec3> rest = points_from_xyz(session.base_positions);
    const int n = a.frames > 0 ? a.frames : 120;
    for (int f = 0; f < n; ++f) {
      const double phase = n > 1 ? std::sin(M_PI * f / (n - 1)) : 1.0;
      out.push_back(to_floats(procedural_pose(rest, *motion, phase).positions));
    }
  } else {
    std::vector<std::vector<float>> files;
    for (const auto& p : a.poses) files.push_back(to_floats(read_pose(p, session.base_vertex_count()).positions));
    const int n = a.frames > 0 ? a.frames : static_cast<int>(files.size());
    for (int f = 0; f < n; ++f) out.push_back(files[f % files.size()]);
  }
  return out;
}

void drive(const DriveArgs& a) {
  Client client(a.server, channel_credentials());
  const std::string token = session_token(a);
  const SessionMesh session = client.join(a.session, token);
  const std::vector<std::vector<float>> poses = make_poses(a, session);
  FrameDecoder decoder(session.rest_positions);
  auto driver = client.drive(a.session, token, a.name);

  std::vector<Clock::time_point> sent_at(poses.size() + 1);  // by pose_id
  std::mutex mutex;
  std::condition_variable answered;
  std::uint64_t newest_answered = 0;
  bool reader_done = false;
  // From a pose's send to the first frame including it: received (read
  // from the stream) and decoded (its positions ready, as an engine uses them).
  std::vector<double> latency_ms, decoded_ms;
  std::vector<std::vector<Vec3>> frames;
  std::size_t frame_count = 0, bytes = 0;
  std::exception_ptr reader_error;

  std::thread reader([&] {
    try {
      while (auto frame = driver->read()) {
        const auto received = Clock::now();
        DecodedFrame d = decoder.decode(*frame);
        const auto decoded = Clock::now();
        std::vector<Vec3> positions;
        if (!a.output.empty()) positions = points_from_xyz(d.positions);
        std::lock_guard lock(mutex);
        ++frame_count;
        bytes += d.encoded_bytes;
        // Latency of each pose once: from its send to the first frame including it.
        if (d.pose_id > newest_answered && d.pose_id < sent_at.size()) {
          latency_ms.push_back(std::chrono::duration<double, std::milli>(received - sent_at[d.pose_id]).count());
          decoded_ms.push_back(std::chrono::duration<double, std::milli>(decoded - sent_at[d.pose_id]).count());
          newest_answered = d.pose_id;
          answered.notify_all();
        }
        if (!a.output.empty()) frames.push_back(std::move(positions));
      }
    } catch (...) {
      reader_error = std::current_exception();
      driver->cancel();
    }
    std::lock_guard lock(mutex);
    reader_done = true;
    answered.notify_all();
  });

  const auto period = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / a.rate));
  const auto start = Clock::now();
  std::uint64_t sent = 0;
  for (std::uint64_t id = 1; id <= poses.size(); ++id) {
    std::this_thread::sleep_until(start + period * (id - 1));
    {
      std::lock_guard lock(mutex);
      sent_at[id] = Clock::now();
    }
    if (!driver->send(id, poses[id - 1])) break;  // the stream ended; finish() says why
    sent = id;
  }
  {
    // Coalescing may skip poses, but the last one is always answered.
    std::unique_lock lock(mutex);
    answered.wait_for(lock, std::chrono::seconds(10), [&] { return reader_done || newest_answered >= sent; });
  }
  driver->writes_done();
  reader.join();
  if (reader_error) std::rethrow_exception(reader_error);
  throw_if_error(driver->finish());

  const double raw = 12.0 * static_cast<double>(session.vertex_count());
  const double mean = frame_count ? static_cast<double>(bytes) / static_cast<double>(frame_count) : 0.0;
  std::printf("poses_sent: %llu\nframes_received: %zu\nposes_answered: %zu\n", static_cast<unsigned long long>(sent),
              frame_count, latency_ms.size());
  // Received: what the network and the server take. Decoded: and the
  // client's decoding, as the Python and C clients' frame times include it.
  std::printf("latency_p50_ms: %.2f\nlatency_p99_ms: %.2f\n", percentile(latency_ms, 0.50), percentile(latency_ms, 0.99));
  std::printf("latency_decoded_p50_ms: %.2f\nlatency_decoded_p99_ms: %.2f\n", percentile(decoded_ms, 0.50),
              percentile(decoded_ms, 0.99));
  std::printf("bytes_per_frame: %.0f\nraw_bytes_per_frame: %.0f\ncompression: %.1fx\n", mean, raw,
              mean > 0.0 ? raw / mean : 0.0);
  if (!a.output.empty()) write_frames(session, frames, a.rate, a.output);
}

// ---------------------------------------------------------------- watch

void watch(const WatchArgs& a) {
  Client client(a.server, channel_credentials());
  const std::string token = session_token(a);
  const SessionMesh session = client.join(a.session, token);
  FrameDecoder decoder(session.rest_positions);
  std::vector<std::vector<Vec3>> frames;
  int count = 0;
  // The Watcher reopens the stream by itself when the server goes away (a
  // restart, the session moving to another replica), from the last version
  // it delivered; the CLI only says so.
  Reconnect reconnect;
  reconnect.on_reconnect = [](const grpc::Status& why, int attempt) {
    std::fprintf(stderr, "stream ended (%s); reconnecting, attempt %d\n", why.error_message().c_str(), attempt);
  };
  auto watcher = client.watch(a.session, token, WatchOptions{.after_version = a.after, .max_vertices = a.max_vertices},
                              std::move(reconnect));
  bool enough = false;
  // The level the recorded frames are at (with --max-vertices): one mesh for all.
  std::shared_ptr<const DecodedLevel> recorded_level;
  while (auto message = watcher->read()) {
    if (message->has_level()) {
      // A level starts (the stream's first message with --max-vertices, and
      // again after a reconnection): its frames follow.
      const DecodedLevel& level = decoder.set_level(message->level());
      std::printf("level %u vertices  %u faces%s\n", level.vertex_count, level.face_count,
                  level.full_detail ? "  (the full mesh)" : "");
      std::fflush(stdout);
      continue;
    }
    const DecodedFrame d = decoder.decode(*message);
    std::string changes;
    for (const auto& c : d.changes)
      changes += (changes.empty() ? "" : ",") + c.client_name() + ":" + std::to_string(c.pose_id()) + ":" +
                 std::to_string(c.vertex_count());
    const std::string level = d.level ? "  level " + std::to_string(d.vertex_count()) : "";
    std::printf("version %llu%s  bytes %zu  max_error %.3g  compute_ms %.2f  changes %s\n",
                static_cast<unsigned long long>(d.version), level.c_str(), d.encoded_bytes, d.max_error,
                d.stats.compute_ms(), changes.empty() ? "-" : changes.c_str());
    std::fflush(stdout);
    if (!a.output.empty()) {
      if (!frames.empty() && d.vertex_count() != frames.back().size()) frames.clear();  // a new level: its frames only
      recorded_level = d.level;
      frames.push_back(points_from_xyz(d.positions));
    }
    if (a.frames > 0 && ++count >= a.frames) {
      watcher->cancel();  // enough: the CANCELLED status below is ours
      enough = true;
      break;
    }
  }
  const grpc::Status status = watcher->finish();
  if (!enough) {
    throw_if_error(status);
    std::fprintf(stderr, "the session was closed\n");
  }
  if (!a.output.empty()) write_frames(level_rest_mesh(session, recorded_level.get()), frames, a.fps, a.output);
}

// ---------------------------------------------------------------- play

void play(const PlayArgs& a) {
  Client client(a.server, channel_credentials());
  const std::string token = session_token(a);
  const SessionMesh session = client.join(a.session, token);
  if (session.skeleton.joints().empty())
    throw std::runtime_error("session " + a.session + " has no skeleton (its upload was not a skinned glTF)");
  FrameDecoder decoder(session.rest_positions);
  ClipPlayback playback;
  playback.speed = a.speed;
  playback.max_rate = a.fps;
  playback.start_seconds = a.start;
  playback.loop = a.loop;
  auto stream = client.play_clip(a.session, token, a.clip, playback, a.name);
  std::vector<std::vector<Vec3>> frames;
  std::size_t bytes = 0;
  int count = 0;  // frames received, written or not
  while (auto frame = stream->read()) {
    const DecodedFrame d = decoder.decode(*frame);
    bytes += d.encoded_bytes;
    if (!a.output.empty()) frames.push_back(points_from_xyz(d.positions));
    if (a.frames > 0 && ++count >= a.frames) stream->cancel();
    std::printf("version %llu  sample %llu  clip_time %.3f s  bytes %zu  max_error %.3g\n",
                static_cast<unsigned long long>(d.version), static_cast<unsigned long long>(d.pose_id), d.clip_seconds,
                d.encoded_bytes, d.max_error);
  }
  const grpc::Status status = stream->finish();
  if (!(a.frames > 0 && status.error_code() == grpc::StatusCode::CANCELLED)) throw_if_error(status);
  if (!a.output.empty()) write_frames(session, frames, a.fps, a.output);
}

void locate(const SessionArgs& a) {
  Client client(a.server, channel_credentials());
  const v1::SessionLocation where = client.locate(a.session, session_token(a));
  std::printf("session_id: %s\nreplica_id: %s\naddress: %s\nhere: %s\n", where.session_id().c_str(),
              where.replica_id().empty() ? "-" : where.replica_id().c_str(),
              where.address().empty() ? "-" : where.address().c_str(), where.here() ? "yes" : "no");
}

// ---------------------------------------------------------------- sessions

void sessions(const std::string& server) {
  Client client(server, channel_credentials());
  client.set_api_key(api_key());
  const auto entries = client.list();
  if (entries.empty()) {
    std::printf("no sessions\n");
    return;
  }
  std::printf("%-24s %-16s %10s %6s %10s %7s %8s\n", "SESSION", "MESH", "VERTICES", "BASE", "VERSION", "DRIVERS",
              "WATCHERS");
  for (const auto& e : entries)
    std::printf("%-24s %-16s %10u %6u %10llu %7u %8u\n", e.session_id().c_str(), e.mesh_hash().c_str(),
                e.vertex_count(), e.base_vertex_count(), static_cast<unsigned long long>(e.version()), e.drivers(),
                e.watchers());
}

void add_session_options(CLI::App* cmd, SessionArgs& a, const char* output_help) {
  cmd->add_option("--session", a.session, "Session id")->required();
  cmd->add_option("--token-file", a.token_file,
                  "File whose first line is the session token (drive, play: the editor's); default: $FILIGREE_TOKEN")
      ->check(CLI::ExistingFile);
  cmd->add_option("--server", a.server, "Server address HOST:PORT");
  cmd->add_option("-o,--output", a.output, output_help);
}

}  // namespace

void add_service_commands(CLI::App& app) {
  auto u = std::make_shared<UploadArgs>();
  CLI::App* up = app.add_subcommand("upload", "Upload a mesh to filigree-server and start a session");
  up->add_option("mesh", u->mesh, "Mesh file (.obj .ply .off .gltf .glb)")->required()->check(CLI::ExistingFile);
  up->add_option("--server", u->server, "Server address HOST:PORT");
  up->add_option("--base-vertices", u->base_vertices, "Base mesh size (default: the server's, 2% of the vertices)");
  auto* t = up->add_option("--threshold", u->threshold, "Performance threshold T of the cut (0: direct recovery only)")
                ->check(CLI::NonNegativeNumber);
  up->add_flag("--whole-mesh", u->whole_mesh, "Whole-mesh optimisation (T = infinity)")->excludes(t);
  up->add_option("--bits", u->bits, "Quantization bits of frame deltas (8-24; default: per frame, the fewest that keep the error within 5e-5 of the diagonal)")->check(CLI::Range(8, 24));
  up->add_option("--name", u->name, "Client name shown to other participants");
  up->add_option("--skinning", u->skinning, "How skeletal poses skin a skinned glTF's base: linear (default) or dual-quaternion");
  up->callback([u] { upload(*u); });

  auto d = std::make_shared<DriveArgs>();
  CLI::App* dr = app.add_subcommand(
      "drive", "Drive a session with poses and report latency and frame size. latency_*: from a pose's send to the "
               "first frame including it, as read from the stream (before decoding); latency_decoded_*: the same "
               "with the frame decoded, as an engine uses it (what the C and Python clients' timings include)");
  add_session_options(dr, *d, "Write the received frames: .glb animation, other formats the last frame");
  auto* m = dr->add_option("--motion", d->motion, "Procedural motion: bend, twist, twist360, wave, bump or fold");
  auto* p = dr->add_option("--poses", d->poses, "Pose files (.pose or a posed base mesh), sent in turn")
                ->check(CLI::ExistingFile)
                ->excludes(m);
  dr->add_option("--rate", d->rate, "Poses per second")->check(CLI::PositiveNumber);
  dr->add_option("--frames", d->frames, "Poses to send (default: 120 for a motion, one per pose file)")
      ->check(CLI::Range(1, 1000000));
  dr->add_option("--name", d->name, "Client name shown to other participants");
  dr->callback([d, m, p] {
    if (m->count() == 0 && p->count() == 0) throw CLI::RequiredError("--motion or --poses");
    drive(*d);
  });

  auto w = std::make_shared<WatchArgs>();
  CLI::App* wa = app.add_subcommand("watch", "Print (and optionally record) a session's frames as they come");
  add_session_options(wa, *w, "Write the received frames: .glb animation, other formats the last frame");
  wa->add_option("--frames", w->frames, "Stop after N frames (default: until the session closes)")
      ->check(CLI::Range(1, 1000000));
  wa->add_option("--after", w->after, "Skip frames up to this version");
  wa->add_option("--fps", w->fps, "Frame rate of the .glb animation")->check(CLI::PositiveNumber);
  wa->add_option("--max-vertices", w->max_vertices,
                 "Watch a level of detail: a coarser mesh of at most N vertices (rounded down to a power of two; the "
                 "base below its size, the full mesh at or above it). -o then writes the level's mesh")
      ->check(CLI::Range(1u, 4294967295u));
  wa->callback([w] { watch(*w); });

  auto pl = std::make_shared<PlayArgs>();
  CLI::App* pc = app.add_subcommand("play", "Play one of a skinned session's animation clips on the server, and record its frames");
  add_session_options(pc, *pl, "Write the received frames: .glb animation, other formats the last frame");
  pc->add_option("--clip", pl->clip, "Clip name (SessionInfo.skeleton.clips; `filigree inspect UPLOAD.glb` lists them)")->required();
  pc->add_option("--speed", pl->speed, "Playback rate")->check(CLI::PositiveNumber);
  pc->add_option("--fps", pl->fps, "Samples per second of clip time at most, and the .glb frame rate")->check(CLI::Range(1.0, 60.0));
  pc->add_option("--start", pl->start, "Clip time of the first sample, in seconds")->check(CLI::NonNegativeNumber);
  pc->add_flag("--loop", pl->loop, "Play until interrupted (with --frames: that many frames)");
  pc->add_option("--frames", pl->frames, "Stop after N frames")->check(CLI::Range(1, 1000000));
  pc->add_option("--name", pl->name, "Client name shown to other participants");
  pc->callback([pl] { play(*pl); });

  auto server = std::make_shared<std::string>(kDefaultServer);
  auto located = std::make_shared<SessionArgs>();
  CLI::App* loc = app.add_subcommand("locate", "Which replica serves a session (replicas sharing Redis); "
                                                "needs a token of the session (FILIGREE_TOKEN or --token-file)");
  loc->add_option("--server", located->server, "Server address HOST:PORT (any replica, or the load balancer)");
  loc->add_option("--session", located->session, "Session id")->required();
  loc->add_option("--token-file", located->token_file, "File holding a token of the session (default: $FILIGREE_TOKEN)");
  loc->callback([located] { locate(*located); });

  CLI::App* ls = app.add_subcommand("sessions", "List the server's sessions");
  ls->add_option("--server", *server, "Server address HOST:PORT");
  ls->callback([server] { sessions(*server); });
}

}  // namespace filigree::cli
