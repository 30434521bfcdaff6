#include "bench/soak/upload_pressure.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <mutex>
#include <thread>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "bench/soak/rss_sampler.h"
#include "filigree/v1/filigree.grpc.pb.h"
#include "support/server_process.h"

namespace filigree::soak {
namespace {

// `mib` MiB of OBJ: comment lines, then one tetrahedron.
std::string padded_obj(int mib) {
  const std::string mesh = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";
  const std::size_t size = static_cast<std::size_t>(mib) << 20;
  std::string line(1023, 'x');
  line.front() = '#';
  line += '\n';
  std::string obj;
  obj.reserve(size);
  while (obj.size() + line.size() + mesh.size() <= size) obj += line;
  obj.append(size - obj.size() - mesh.size(), '\n');
  return obj + mesh;
}

}  // namespace

UploadPressureSummary run_upload_pressure(const std::string& server_binary, int uploads, int upload_mib, int max_memory_mib,
                                          Failures& failures) {
  UploadPressureSummary summary;
  summary.uploads = uploads;
  summary.limit_bytes = static_cast<std::uint64_t>(max_memory_mib) << 20;
  test::ServerProcess server(server_binary, {"--max-memory", std::to_string(max_memory_mib),
                                             "--max-mesh-bytes", std::to_string((upload_mib + 1) << 20)});
  const std::string obj = padded_obj(upload_mib);
  RssSampler rss(server.pid(), std::chrono::milliseconds(20), failures);
  rss.start();
  std::mutex mutex;
  std::vector<std::thread> threads;
  for (int i = 0; i < uploads; ++i)
    threads.emplace_back([&] {
      // One connection each, as separate clients would have.
      auto stub = v1::Filigree::NewStub(grpc::CreateChannel(server.address(), grpc::InsecureChannelCredentials()));
      grpc::ClientContext ctx;
      ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(300));
      auto stream = stub->CreateSession(&ctx);
      v1::CreateSessionRequest message;
      message.mutable_begin()->set_format("obj");
      message.mutable_begin()->set_total_bytes(obj.size());
      message.mutable_begin()->mutable_options()->set_base_vertices(4);
      bool sending = stream->Write(message);
      for (std::size_t at = 0; sending && at < obj.size(); at += 1 << 20) {
        message.set_chunk(obj.substr(at, 1 << 20));
        sending = stream->Write(message);
      }
      stream->WritesDone();
      v1::CreateSessionResponse r;
      bool created = false;
      while (stream->Read(&r)) created |= r.has_created();
      const grpc::Status status = stream->Finish();
      std::lock_guard lock(mutex);
      if (status.ok() && created) {
        ++summary.created;
      } else if (status.error_code() == grpc::StatusCode::RESOURCE_EXHAUSTED) {
        ++summary.refused;
      } else {
        failures.add("a concurrent upload ended " + std::to_string(status.error_code()) + ": " + status.error_message());
      }
    });
  for (auto& t : threads) t.join();
  rss.stop();
  for (const auto& sample : rss.samples()) summary.peak_rss_bytes = std::max(summary.peak_rss_bytes, sample.bytes);
  if (summary.refused == 0) failures.add("no concurrent upload was refused: --max-memory did not bite");
  // Reserved are the uploads' declared bytes; parsing one (one preprocessing
  // slot) adds up to twice its size while it reads the text.
  const std::uint64_t allowance = summary.limit_bytes + (static_cast<std::uint64_t>(upload_mib) << 21);
  if (summary.peak_rss_bytes > allowance)
    failures.add("server RSS peaked at " + std::to_string(summary.peak_rss_bytes >> 20) + " MiB under --max-memory " +
                 std::to_string(max_memory_mib) + " (allowed with one upload's parse: " + std::to_string(allowance >> 20) +
                 " MiB)");
  server.terminate();
  return summary;
}

}  // namespace filigree::soak
