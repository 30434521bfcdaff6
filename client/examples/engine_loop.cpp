// engine_loop: what a game engine does with Filigree, in one file.
//
//   engine_loop --server 127.0.0.1:50051 --mesh armadillo.obj [--frames 300 | --seconds 5] [--rate 60]
//   FILIGREE_TOKEN=EDITOR_TOKEN engine_loop --server 127.0.0.1:50051 --session ID [--frames 300]
//
// It uploads a mesh (or joins a session), then for --seconds drives a
// procedural bend of the base mesh at --rate Hz from a writer thread (the
// engine's animation tick) while a reader thread receives and decodes the
// detailed frames (what the renderer would upload to the GPU). At the end it
// prints frames received, the pose → frame latency (p50/p99) and the mean
// compressed frame size against raw float32 positions.

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <fstream>
#include <iterator>
#include <mutex>
#include <span>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include <filigree/client.h>

namespace {

using Clock = std::chrono::steady_clock;

struct Args {
  std::string server = "127.0.0.1:50051";
  std::string mesh, session, token;
  double seconds = 5.0, rate = 60.0;
  long frames = 0;  // poses to send; 0: seconds × rate (the C example takes --frames too)
};

constexpr const char* kUsage =
    "usage: engine_loop [--server HOST:PORT] (--mesh FILE | --session ID, with $FILIGREE_TOKEN the editor token)\n"
    "                   [--frames N | --seconds S] [--rate HZ]\n";

Args parse_args(int argc, char** argv) {
  Args a;
  for (int i = 1; i < argc; ++i) {
    const std::string flag = argv[i];
    if (flag == "-h" || flag == "--help") {
      std::fputs(kUsage, stdout);
      std::exit(0);
    }
    if (i + 1 >= argc) throw std::invalid_argument("missing value after " + flag);
    const std::string value = argv[++i];
    if (flag == "--server") a.server = value;
    else if (flag == "--mesh") a.mesh = value;
    else if (flag == "--session") a.session = value;
    else if (flag == "--seconds") a.seconds = std::stod(value);
    else if (flag == "--frames") a.frames = std::stol(value);
    else if (flag == "--rate") a.rate = std::stod(value);
    else throw std::invalid_argument("unknown option " + flag);
  }
  if (a.mesh.empty() == a.session.empty()) throw std::invalid_argument("give --mesh FILE or --session ID");
  // The token from the environment: a command line is visible to every user (ps).
  if (const char* token = std::getenv("FILIGREE_TOKEN")) a.token = token;
  if (!a.session.empty() && a.token.empty()) throw std::invalid_argument("joining a session: set FILIGREE_TOKEN");
  if (!(a.rate > 0.0 && a.seconds > 0.0 && a.frames >= 0))
    throw std::invalid_argument("--rate and --seconds must be positive, --frames not negative");
  return a;
}

std::string read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error("cannot read " + path);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// The engine's animation, a stand-in for a skeleton: the half of the base
// mesh beyond the middle of its longest axis a bends (rotates in the plane of
// a and the next axis b) by up to ±40° at its tip, swinging at 0.5 Hz.
class Bend {
 public:
  explicit Bend(std::vector<float> rest) : rest_(std::move(rest)) {
    float lo[3] = {1e30f, 1e30f, 1e30f}, hi[3] = {-1e30f, -1e30f, -1e30f};
    for (std::size_t i = 0; i < rest_.size(); ++i) lo[i % 3] = std::min(lo[i % 3], rest_[i]), hi[i % 3] = std::max(hi[i % 3], rest_[i]);
    for (int c = 0; c < 3; ++c)
      if (hi[c] - lo[c] > hi[a_] - lo[a_]) a_ = c;
    b_ = (a_ + 1) % 3;
    mid_ = 0.5f * (lo[a_] + hi[a_]);
    half_ = std::max(0.5f * (hi[a_] - lo[a_]), 1e-12f);
    center_b_ = 0.5f * (lo[b_] + hi[b_]);
  }

  // The pose at time t (seconds): base positions, 3 floats per base vertex.
  void pose_at(double t, std::vector<float>& out) const {
    out = rest_;
    constexpr double kPi = 3.14159265358979323846;
    const double max_angle = 40.0 * kPi / 180.0 * std::sin(2.0 * kPi * 0.5 * t);
    for (std::size_t v = 0; v < rest_.size() / 3; ++v) {
      const float u = rest_[3 * v + a_] - mid_;
      if (u <= 0.0f) continue;
      // Rotate about the line through the middle, more the further out.
      const double angle = max_angle * (u / half_);
      const double da = u, db = rest_[3 * v + b_] - center_b_;
      out[3 * v + a_] = static_cast<float>(mid_ + da * std::cos(angle) - db * std::sin(angle));
      out[3 * v + b_] = static_cast<float>(center_b_ + da * std::sin(angle) + db * std::cos(angle));
    }
  }

 private:
  std::vector<float> rest_;
  int a_ = 0, b_ = 1;
  float mid_ = 0.0f, half_ = 1.0f, center_b_ = 0.0f;
};

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(p * (v.size() - 1) + 0.5)];
}

void run(const Args& args) {
  filigree::Client client(args.server);

  // 1. A session: upload the mesh (editor token comes back) or join one.
  std::string session_id = args.session, token = args.token;
  filigree::SessionMesh mesh;
  bool created = false;
  if (!args.mesh.empty()) {
    const std::string bytes = read_file(args.mesh);
    const std::string format = args.mesh.substr(args.mesh.find_last_of('.') + 1);
    // Progress of the upload and of the server's preprocessing, in 10% steps.
    auto progress = [shown = std::string()](const std::string& stage, double f) mutable {
      const std::string line = stage + " " + std::to_string(static_cast<int>(f * 10.0) * 10) + "%";
      if (line != shown) std::fprintf(stderr, "%s\n", (shown = line).c_str());
    };
    auto session = client.create_session(bytes, format, {}, "engine_loop", progress);
    session_id = session.session_id;
    token = session.editor_token;
    mesh = std::move(session.mesh);
    created = true;
    std::printf("session %s (%s), viewer token %s\n", session_id.c_str(), session.cached ? "cached" : "preprocessed",
                session.viewer_token.c_str());
  } else {
    mesh = client.join(session_id, token);
  }
  std::printf("%zu vertices, %zu base vertices, %u-bit deltas\n", mesh.vertex_count(), mesh.base_vertex_count(),
              mesh.quantization_bits);

  // 2. The decoder keeps the rest mesh; frames are deltas from it.
  filigree::FrameDecoder decoder(mesh.rest_positions);
  const Bend bend(mesh.base_positions);
  auto driver = client.drive(session_id, token, "engine_loop");

  const auto period = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / args.rate));
  const auto poses = args.frames > 0 ? static_cast<std::uint64_t>(args.frames)
                                     : static_cast<std::uint64_t>(args.seconds * args.rate);
  std::vector<Clock::time_point> sent_at(poses + 1);  // by pose_id
  std::mutex sent_mutex;
  std::atomic<std::uint64_t> last_sent{0}, newest_answered{0};

  // 3. Reader thread: frames in, decoded, latency from the pose they answer.
  std::vector<double> latency_ms;
  std::size_t frames = 0, bytes = 0;
  double decode_ms = 0.0;
  std::exception_ptr reader_error;
  std::thread reader([&] {
    try {
      while (auto frame = driver->read()) {
        const auto received = Clock::now();
        const filigree::DecodedFrame decoded = decoder.decode(*frame);  // → your vertex buffer
        decode_ms += std::chrono::duration<double, std::milli>(Clock::now() - received).count();
        ++frames;
        bytes += decoded.encoded_bytes;
        // A frame answers our newest pose it includes; count each pose once.
        if (decoded.pose_id > newest_answered && decoded.pose_id <= poses) {
          newest_answered = decoded.pose_id;
          std::lock_guard lock(sent_mutex);
          latency_ms.push_back(std::chrono::duration<double, std::milli>(received - sent_at[decoded.pose_id]).count());
        }
      }
    } catch (...) {  // a frame that does not decode: stop driving, report it below
      reader_error = std::current_exception();
      driver->cancel();
    }
  });

  // 4. Writer (this thread, the engine tick): a pose every 1/rate seconds.
  std::vector<float> pose;
  const auto start = Clock::now();
  for (std::uint64_t id = 1; id <= poses; ++id) {
    std::this_thread::sleep_until(start + period * (id - 1));
    bend.pose_at(std::chrono::duration<double>(Clock::now() - start).count(), pose);
    {
      std::lock_guard lock(sent_mutex);
      sent_at[id] = Clock::now();
    }
    if (!driver->send(id, pose)) break;  // the stream ended: finish() below says why
    last_sent = id;
  }
  // Give the last pose a moment to come back, then end the stream.
  for (auto deadline = Clock::now() + std::chrono::seconds(2); newest_answered < last_sent && Clock::now() < deadline;)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  driver->writes_done();
  reader.join();
  if (reader_error) std::rethrow_exception(reader_error);
  filigree::throw_if_error(driver->finish());
  if (created) client.close(session_id, token);

  // 5. The numbers.
  const double raw = 12.0 * mesh.vertex_count();
  const double mean_bytes = frames ? double(bytes) / frames : 0.0;
  std::printf("poses sent        %llu at %.0f Hz\n", static_cast<unsigned long long>(last_sent.load()), args.rate);
  std::printf("frames received   %zu\n", frames);
  std::printf("latency ms        p50 %.2f  p99 %.2f  (%zu poses answered)\n", percentile(latency_ms, 0.50),
              percentile(latency_ms, 0.99), latency_ms.size());
  std::printf("bytes per frame   %.0f (raw float32 %.0f, %.1fx smaller)\n", mean_bytes, raw,
              mean_bytes > 0 ? raw / mean_bytes : 0.0);
  std::printf("decode ms/frame   %.2f\n", frames ? decode_ms / frames : 0.0);
}

}  // namespace

int main(int argc, char** argv) {
  try {
    run(parse_args(argc, argv));
    return 0;
  } catch (const filigree::ClientError& e) {
    std::fprintf(stderr, "engine_loop: %s\n", e.what());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "engine_loop: error: %s\n", e.what());
  }
  return 1;
}
