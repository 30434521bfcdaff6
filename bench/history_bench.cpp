// What the edit history costs (server/edit_history.h: every pose a session
// merges is recorded), on loopback, on the ≈150k and the ≥ 1M mesh of the
// service bench (bench/service_harness.h):
//
// - pose → frame p50 of the whole-body drive (the service bench's closed
//   loop, one watcher; one Drive stream, so one entry every pose extends)
//   on two servers of one build, one keeping the history (the defaults:
//   1000 entries, 64 MiB) and one without it (--history-entries 0). They
//   alternate round by round, each round starting with the other one, so
//   that this machine's drift falls on both; the cost is the median of each
//   round's on / off − 1 (two drives a minute or less apart), with the
//   medians of both beside it;
//   Beside it, the history's own time a pose measured in this process
//   (EditHistory::record_pose of the same poses into one entry, median),
//   and serialize() of that history (what a maintenance tick writes after
//   a change): a cost free of the machine's noise;
// - the bytes an entry holds (GetHistory's History.bytes / entries) for a
//   whole-body gesture and a local one (the service bench's bump: partial
//   poses), and per base vertex it changed (poses are of the base mesh: the
//   history holds base vertices only);
// - undo latency: after a change of one gesture (SubmitPose, its frame
//   seen on a Watch stream), the Undo call's round trip, and the time until
//   the frame including the undo (a version above the answer's
//   accepted_at_version) arrives on the Watch stream; p50 and p99; also
//   with the session's history at its bound (1000 entries or 64 MiB), as
//   after a long session: an undo is answered once the whole history is
//   written durably.
//
// Target: the history costs ≤ 5% of pose → frame p50 on both meshes.
//
// Usage: filigree_bench_history [server-binary] [--rounds N] (alternating
//        rounds a mesh; default 9) [--poses N] (poses a drive; default 300,
//        120 at ≥ 1M: fewer make each round's two drives closer in time)
//        [--undos N] (undos a row; default 40) [--mesh medium|large] (one
//        mesh only) [--full-history] (the rounds' session with the history
//        starts with it at its bound: each maintenance tick of a drive
//        then writes all of it)

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <span>
#include <stdexcept>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "bench/sample_stats.h"
#include "bench/service_harness.h"
#include "filigree/v1/filigree.grpc.pb.h"
#include "server/edit_history.h"

namespace {

using namespace filigree;
using namespace filigree::bench;

constexpr double kTarget = 0.05;
const std::string kAuthor = "bench";

double ms_since(Clock::time_point t) { return std::chrono::duration<double, std::milli>(Clock::now() - t).count(); }

// A Watch stream on its own thread, keeping each frame's version and when
// it arrived.
class FrameLog {
 public:
  FrameLog(v1::Filigree::Stub& stub, const v1::CreateSessionResponse::Created& created)
      : ctx_(context(created.info().session_id(), created.viewer_token())) {
    v1::WatchRequest r;
    r.set_session_id(created.info().session_id());
    r.set_frame_format(v1::FRAME_FORMAT_CHUNKED);
    reader_ = stub.Watch(ctx_.get(), r);
    thread_ = std::thread([this] {
      v1::Frame f;
      while (reader_->Read(&f)) {
        std::lock_guard lock(mutex_);
        arrived_.emplace_back(f.version(), Clock::now());
        changed_.notify_all();
      }
      std::lock_guard lock(mutex_);
      ended_ = true;
      changed_.notify_all();
    });
  }
  ~FrameLog() {
    ctx_->TryCancel();
    thread_.join();
    reader_->Finish();
  }
  FrameLog(const FrameLog&) = delete;
  FrameLog& operator=(const FrameLog&) = delete;

  // When the first frame above `version` arrived (waits for it).
  Clock::time_point above(std::uint64_t version) {
    std::unique_lock lock(mutex_);
    for (;;) {
      for (const auto& [v, t] : arrived_)
        if (v > version) return t;
      if (ended_) throw std::runtime_error("the Watch stream ended");
      changed_.wait(lock);
    }
  }

 private:
  std::unique_ptr<grpc::ClientContext> ctx_;
  std::unique_ptr<grpc::ClientReader<v1::Frame>> reader_;
  std::thread thread_;
  std::mutex mutex_;
  std::condition_variable changed_;
  std::vector<std::pair<std::uint64_t, Clock::time_point>> arrived_;
  bool ended_ = false;
};

// `gestures` gestures of `poses` poses each of `motion` on one Drive stream
// (gesture ids 1, 2, …), each pose waiting for its frame.
void drive_gestures(v1::Filigree::Stub& stub, const v1::CreateSessionResponse::Created& created, const MotionPoses& motions,
                    Movement motion, int gestures, int poses) {
  const std::string id = created.info().session_id();
  auto ctx = context(id, created.editor_token());
  auto drive = stub.Drive(ctx.get());
  std::uint64_t pose_id = 0;
  for (int g = 1; g <= gestures; ++g)
    for (int p = 1; p <= poses; ++p) {
      v1::DriveRequest r;
      r.set_session_id(id);
      r.set_pose_id(++pose_id);
      r.set_client_name(kAuthor);
      r.set_gesture_id(static_cast<std::uint64_t>(g));
      r.set_frame_format(v1::FRAME_FORMAT_CHUNKED);
      motions.fill(r, motion, static_cast<int>(pose_id));
      drive->Write(r);
      v1::Frame f;
      do {
        if (!drive->Read(&f)) throw std::runtime_error("a gesture's drive ended: " + drive->Finish().error_message());
      } while (f.pose_id() != pose_id);
    }
  drive->WritesDone();
  for (v1::Frame f; drive->Read(&f);) {
  }
  const grpc::Status status = drive->Finish();
  if (!status.ok()) throw std::runtime_error("a gesture's drive failed: " + status.error_message());
}

v1::History get_history(v1::Filigree::Stub& stub, const v1::CreateSessionResponse::Created& created) {
  v1::GetHistoryRequest r;
  r.set_session_id(created.info().session_id());
  v1::History h;
  const grpc::Status status = stub.GetHistory(context(r.session_id(), created.viewer_token()).get(), r, &h);
  if (!status.ok()) throw std::runtime_error("GetHistory: " + status.error_message());
  return h;
}

// Whole-body changes of an author of their own, one gesture each, until the
// history drops its oldest entries: it is at its bound. The newest entry's
// description (first_seq, bytes).
v1::History fill_history(v1::Filigree::Stub& stub, const v1::CreateSessionResponse::Created& created) {
  const std::string id = created.info().session_id();
  const MotionPoses motions(created);
  for (int i = 1; i <= 20000; ++i) {
    v1::DriveRequest change;
    change.set_session_id(id);
    change.set_client_name("filler");
    change.set_gesture_id(static_cast<std::uint64_t>(100000 + i));
    motions.fill(change, Movement::kWholeBody, i);
    v1::SubmitPoseResponse accepted;
    const grpc::Status status = stub.SubmitPose(context(id, created.editor_token()).get(), change, &accepted);
    if (!status.ok()) throw std::runtime_error("SubmitPose: " + status.error_message());
    if (i % 25 != 0) continue;
    v1::GetHistoryRequest r;
    r.set_session_id(id);
    r.set_newest(1);
    v1::History h;
    if (!stub.GetHistory(context(id, created.viewer_token()).get(), r, &h).ok()) throw std::runtime_error("GetHistory failed");
    if (h.first_seq() > 1) return h;
  }
  throw std::runtime_error("the history never reached its bound");
}

struct EntrySize {
  std::size_t entries = 0, bytes = 0, vertices = 0;  // kept; History.bytes; base vertices listed over the entries
};

// Gestures on a fresh session; the size of its history.
EntrySize entry_size(v1::Filigree::Stub& stub, const std::string& bytes, Movement motion, int gestures, int poses) {
  const auto created = upload(stub, bytes);
  drive_gestures(stub, created, MotionPoses(created), motion, gestures, poses);
  const v1::History h = get_history(stub, created);
  EntrySize out;
  out.entries = static_cast<std::size_t>(h.entries_size());
  out.bytes = h.bytes();
  for (const v1::HistoryEntry& e : h.entries()) out.vertices += static_cast<std::size_t>(e.base_vertices_size());
  return out;
}

struct DirectTime {
  std::size_t base_vertices = 0;
  double record_us = 0.0, serialize_ms = 0.0;  // medians: a pose recorded; the history serialized
  std::size_t full_entries = 0, full_bytes = 0;  // the history at its bound
  double full_serialize_ms = 0.0;                // and serialize() of it, median
};

// The history's own work in this process for `poses` whole-body poses of
// the drive, as one stream's gesture (one entry every pose extends); then
// whole-body gestures of one pose each until it is at its bound.
DirectTime direct_time(const v1::CreateSessionResponse::Created& created, int poses) {
  const auto& base = created.info().base().positions();
  DirectTime out;
  out.base_vertices = static_cast<std::size_t>(base.size()) / 3;
  server::EditHistory history(out.base_vertices, {});
  std::vector<float> pose(base.begin(), base.end());
  const MotionPoses motions(created);
  std::vector<double> record, serialize;
  for (int p = 1; p <= poses; ++p) {
    v1::DriveRequest r;
    motions.fill(r, Movement::kWholeBody, p);
    const std::span<const float> after(r.positions().data(), static_cast<std::size_t>(r.positions_size()));
    const auto start = Clock::now();
    history.record_pose({kAuthor, 0, server::unix_seconds(), static_cast<std::uint64_t>(p)}, v1::HistoryEntry::KIND_POSE, {},
                        pose, after);
    record.push_back(1000.0 * ms_since(start));
    std::copy(after.begin(), after.end(), pose.begin());
  }
  for (int i = 0; i < 20; ++i) {
    const auto start = Clock::now();
    const std::string bytes = history.serialize();
    serialize.push_back(ms_since(start));
    if (bytes.empty()) throw std::runtime_error("an empty history");
  }
  out.record_us = median(record);
  out.serialize_ms = median(serialize);
  for (int g = 1; static_cast<std::size_t>(g) == history.size(); ++g) {  // until an entry is dropped
    v1::DriveRequest r;
    motions.fill(r, Movement::kWholeBody, poses + g);
    const std::span<const float> after(r.positions().data(), static_cast<std::size_t>(r.positions_size()));
    history.record_pose({kAuthor, static_cast<std::uint64_t>(g), server::unix_seconds(), static_cast<std::uint64_t>(poses + g)},
                        v1::HistoryEntry::KIND_POSE, {}, pose, after);
    std::copy(after.begin(), after.end(), pose.begin());
  }
  out.full_entries = history.size();
  out.full_bytes = history.bytes();
  serialize.clear();
  for (int i = 0; i < 5; ++i) {
    const auto start = Clock::now();
    const std::string bytes = history.serialize();
    serialize.push_back(ms_since(start));
  }
  out.full_serialize_ms = median(serialize);
  return out;
}

struct UndoTimes {
  std::vector<double> call, frame;  // ms from sending Undo: its answer, the frame including it on the Watch stream
  std::size_t not_done = 0;
  std::size_t entries = 0, bytes = 0;  // the history at the start (full: at its bound)
};

// `undos` times: a change of `motion` (one gesture, SubmitPose), its frame
// seen, then the author's Undo. `full`: the history filled to its bound first.
UndoTimes undo_latency(v1::Filigree::Stub& stub, const std::string& bytes, Movement motion, int undos, bool full) {
  const auto created = upload(stub, bytes);
  const std::string id = created.info().session_id();
  const MotionPoses motions(created);
  UndoTimes out;
  if (full) {
    const v1::History h = fill_history(stub, created);
    out.bytes = h.bytes();
    out.entries = static_cast<std::size_t>(get_history(stub, created).entries_size());
  }
  FrameLog frames(stub, created);
  for (int i = 1; i <= undos; ++i) {
    v1::DriveRequest change;
    change.set_session_id(id);
    change.set_client_name(kAuthor);
    change.set_gesture_id(static_cast<std::uint64_t>(1000 + i));
    motions.fill(change, motion, 7 * i);  // a pose unlike the one before
    v1::SubmitPoseResponse accepted;
    grpc::Status status = stub.SubmitPose(context(id, created.editor_token()).get(), change, &accepted);
    if (!status.ok()) throw std::runtime_error("SubmitPose: " + status.error_message());
    frames.above(accepted.accepted_at_version());  // the change is in a frame: the session is idle
    v1::UndoRequest undo;
    undo.set_session_id(id);
    undo.set_client_name(kAuthor);
    v1::UndoResponse answer;
    const auto sent = Clock::now();
    status = stub.Undo(context(id, created.editor_token()).get(), undo, &answer);
    out.call.push_back(ms_since(sent));
    if (!status.ok()) throw std::runtime_error("Undo: " + status.error_message());
    if (answer.outcome() != v1::UndoResponse::OUTCOME_DONE) {
      ++out.not_done;
      continue;
    }
    out.frame.push_back(std::chrono::duration<double, std::milli>(frames.above(answer.accepted_at_version()) - sent).count());
  }
  return out;
}

struct Cost {
  std::string mesh;
  std::size_t vertices = 0;
  double cost = 0.0;    // the median of the rounds' on / off − 1
  double direct = 0.0;  // record_pose's median over the median p50 without the history
};

Cost compare(const std::string& binary, const Case& c, const std::string& bytes, int rounds, int poses_asked, int undos,
             bool full_history) {
  const std::size_t n = c.mesh.vertex_count();
  const int poses = poses_asked > 0 ? poses_asked : n > 500000 ? 120 : 300;
  BenchServer on(binary, "history_on"), off(binary, "history_off", {"--history-entries", "0"});
  const auto on_session = upload(*on.stub, bytes), off_session = upload(*off.stub, bytes);
  std::printf("\n## %s (%zu vertices)\n\n", c.name.c_str(), n);
  if (full_history) {
    const v1::History h = fill_history(*on.stub, on_session);
    std::printf("The session with the history starts with it at its bound: %.1f MiB, oldest entry %llu.\n\n",
                static_cast<double>(h.bytes()) / 1048576.0, static_cast<unsigned long long>(h.first_seq()));
  }
  run(*on.stub, on_session, 1, 20);  // the first drive of each: caches, allocator, the first keyframe
  run(*off.stub, off_session, 1, 20);
  std::printf("Pose → frame, whole body, 1 watcher, %d poses a drive, each round starting with the other server:\n\n"
              "| round | history | p50 ms | p99 ms | compute p50 ms | encode p50 ms | other p50 ms |\n|---:|---|---:|---:|---:|---:|---:|\n",
              poses);
  std::fflush(stdout);
  std::vector<double> p50[2], other[2], ratio;
  for (int r = 0; r < rounds; ++r) {
    double round_p50[2] = {0.0, 0.0};
    for (int i = 0; i < 2; ++i) {
      const int k = (r + i) % 2;  // 0: on, 1: off
      const Result res = k == 0 ? run(*on.stub, on_session, 1, poses) : run(*off.stub, off_session, 1, poses);
      if (res.p50 == 0.0) throw std::runtime_error("a drive ended early");
      round_p50[k] = res.p50;
      p50[k].push_back(res.p50);
      other[k].push_back(res.other_p50);
      std::printf("| %d | %s | %.2f | %.2f | %.2f | %.2f | %.2f |\n", r + 1, k == 0 ? "on" : "off", res.p50, res.p99, res.compute_p50,
                  res.encode_p50, res.other_p50);
      std::fflush(stdout);
    }
    ratio.push_back(round_p50[0] / round_p50[1]);
  }
  const v1::History driven = get_history(*on.stub, on_session);
  const DirectTime d = direct_time(on_session, 300);
  Cost cost{c.name, n, median(ratio) - 1.0, d.record_us / 1000.0 / median(p50[1])};
  std::printf("\n| history | p50 ms (median of %d rounds) | other p50 ms |\n|---|---:|---:|\n| off | %.2f | %.2f |\n"
              "| on | %.2f | %.2f |\n\n"
              "Rounds' on / off: median %.3f (cost %+.1f%%), range %.3f–%.3f; medians' ratio %.3f. The driven session's history "
              "after them: %d entries, %.1f KiB.\n\n"
              "In this process, the same poses into one entry (%zu base vertices a pose): EditHistory::record_pose %.1f µs a pose "
              "(median; %.3f%% of the p50 without the history), serialize() of that history %.3f ms; filled to its bound (%zu entries, "
              "%.1f MiB), serialize() %.1f ms (under the session's lock when a maintenance tick, an undo, a redo or a checkpoint "
              "saves it).\n",
              rounds, median(p50[1]), median(other[1]), median(p50[0]), median(other[0]), median(ratio), 100.0 * cost.cost,
              *std::min_element(ratio.begin(), ratio.end()), *std::max_element(ratio.begin(), ratio.end()),
              median(p50[0]) / median(p50[1]), driven.entries_size(), static_cast<double>(driven.bytes()) / 1024.0,
              d.base_vertices, d.record_us, 100.0 * cost.direct, d.serialize_ms, d.full_entries,
              static_cast<double>(d.full_bytes) / 1048576.0, d.full_serialize_ms);

  // The bytes of an entry: 4 gestures of 20 poses each.
  std::printf("\nBytes an entry holds (History.bytes / entries kept), 4 gestures of 20 poses on a fresh session:\n\n"
              "| gesture | entries kept | History.bytes KiB | bytes / entry | base vertices / entry | bytes / base vertex |\n"
              "|---|---:|---:|---:|---:|---:|\n");
  for (const Movement m : {Movement::kWholeBody, Movement::kLocal}) {
    const EntrySize e = entry_size(*on.stub, bytes, m, 4, 20);
    const double per_entry = e.entries ? static_cast<double>(e.bytes) / static_cast<double>(e.entries) : 0.0;
    const double per_vertex = e.vertices ? static_cast<double>(e.bytes) / static_cast<double>(e.vertices) : 0.0;
    std::printf("| %s | %zu | %.1f | %.0f | %.0f | %.1f |\n", m == Movement::kWholeBody ? "whole body" : "local bump", e.entries,
                static_cast<double>(e.bytes) / 1024.0, per_entry,
                e.entries ? static_cast<double>(e.vertices) / static_cast<double>(e.entries) : 0.0, per_vertex);
    std::fflush(stdout);
  }

  // Undo latency, with the history.
  std::printf("\nUndo, %d a row, each after a change of one gesture whose frame was seen:\n\n| change undone | undos done | "
              "Undo call p50 ms | p99 ms | to its frame on a Watch p50 ms | p99 ms |\n|---|---:|---:|---:|---:|---:|\n",
              undos);
  for (const auto& [m, full] : {std::pair{Movement::kWholeBody, false}, {Movement::kLocal, false}, {Movement::kWholeBody, true}}) {
    const UndoTimes u = undo_latency(*on.stub, bytes, m, undos, full);
    char what[160];
    std::snprintf(what, sizeof what, "%s%s", m == Movement::kWholeBody ? "whole body" : "local bump",
                  full ? ", the history at its bound" : "");
    if (full)
      std::snprintf(what + std::strlen(what), sizeof what - std::strlen(what), " (%zu entries, %.1f MiB)", u.entries,
                    static_cast<double>(u.bytes) / 1048576.0);
    std::printf("| %s | %zu | %.2f | %.2f | %.2f | %.2f |\n", what, u.frame.size(), percentile(u.call, 0.5),
                percentile(u.call, 0.99), percentile(u.frame, 0.5), percentile(u.frame, 0.99));
    if (u.not_done) std::printf("(%zu undos did not answer OUTCOME_DONE)\n", u.not_done);
    std::fflush(stdout);
  }
  return cost;
}

int main_impl(int argc, char** argv) {
  std::string binary = FILIGREE_SERVER_BINARY;
  int rounds = 9, poses = 0, undos = 40;
  bool full_history = false;
  std::vector<std::string> sizes{"medium", "large"};
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--rounds" && i + 1 < argc) {
      rounds = std::max(1, std::stoi(argv[++i]));
    } else if (a == "--poses" && i + 1 < argc) {
      poses = std::max(1, std::stoi(argv[++i]));
    } else if (a == "--undos" && i + 1 < argc) {
      undos = std::max(1, std::stoi(argv[++i]));
    } else if (a == "--full-history") {
      full_history = true;
    } else if (a == "--mesh" && i + 1 < argc) {
      sizes = {argv[++i]};
    } else {
      binary = a;
    }
  }
  std::printf("# What the edit history costs (%s%s)\n", binary.c_str(), full_history ? ", the history at its bound" : "");
  std::vector<Cost> costs;
  for (const std::string& size : sizes) {
    const Case c = bench_mesh(size);
    costs.push_back(compare(binary, c, obj_bytes(c.mesh), rounds, poses, undos, full_history));
  }
  std::printf("\nTarget: the history costs ≤ %.0f%% of pose → frame p50 (median of the rounds' on / off − 1):", 100.0 * kTarget);
  bool met = true;
  for (const Cost& c : costs) {
    std::printf(" %s (%zu) %+.1f%%%s", c.mesh.c_str(), c.vertices, 100.0 * c.cost, &c == &costs.back() ? "" : ";");
    met = met && c.cost <= kTarget;
  }
  std::printf(": %s. The history's own time a pose measured in this process:", met ? "met" : "not met");
  for (const Cost& c : costs) std::printf(" %.3f%%%s", 100.0 * c.direct, &c == &costs.back() ? ".\n" : ",");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return main_impl(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "filigree_bench_history: %s\n", e.what());
    return 1;
  }
}
