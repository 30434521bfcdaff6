#pragma once
// The server's resident memory over the run: VmRSS from /proc/<pid>/status,
// sampled on a thread of its own, and the verdict on its growth.

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "bench/soak/failures.h"

namespace filigree::soak {

struct RssSample {
  double seconds = 0.0;      // since start()
  std::uint64_t bytes = 0;
};

class RssSampler {
 public:
  RssSampler(int pid, std::chrono::milliseconds every, Failures& failures);
  ~RssSampler();
  void start();  // takes a sample at once, then one every `every`
  void stop();   // takes a last sample and joins
  std::vector<RssSample> samples() const;
  std::uint64_t latest_bytes() const;

 private:
  void sample(double seconds);

  const int pid_;
  const std::chrono::milliseconds every_;
  Failures& failures_;
  std::chrono::steady_clock::time_point start_;
  mutable std::mutex mutex_;
  std::condition_variable stop_cv_;
  bool stopping_ = false;
  bool gone_reported_ = false;
  std::vector<RssSample> samples_;
  std::thread thread_;
};

// Growth after warm-up: the sample at the end of warm-up is the baseline, the
// last sample (taken as the load stops) the end; growth = end / baseline − 1.
// The maximum after warm-up is reported too, but a transient peak (an upload
// being parsed) is not a leak: a leak shows at the end.
struct MemoryVerdict {
  bool judged = false;  // some sample lies after warm-up
  double warmup_seconds = 0.0;
  std::uint64_t warmup_end = 0, max = 0, end = 0;
  double growth = 0.0;      // (end − warmup_end) / warmup_end
  double max_growth = 0.0;  // (max − warmup_end) / warmup_end
};

MemoryVerdict judge_memory(const std::vector<RssSample>& samples, double warmup_seconds);

// VmRSS of `pid` in bytes; 0 if the process is gone (a zombie has no VmRSS).
std::uint64_t resident_bytes(int pid);
// CPU time (user + system) `pid` has used, in seconds; for the summary.
double cpu_seconds(int pid);

}  // namespace filigree::soak
