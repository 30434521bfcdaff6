#include "bench/soak/rss_sampler.h"

#include <algorithm>
#include <fstream>
#include <iterator>
#include <sstream>

#include <unistd.h>

namespace filigree::soak {

std::uint64_t resident_bytes(int pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("VmRSS:", 0) == 0) return 1024ull * std::stoull(line.substr(6));  // "VmRSS:   123 kB"
  return 0;
}

double cpu_seconds(int pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/stat");
  std::string stat((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  // Fields after the command name (which may hold spaces, so after its ')'):
  // state is field 3, utime 14, stime 15.
  const auto paren = stat.rfind(')');
  if (paren == std::string::npos) return 0.0;
  std::istringstream fields(stat.substr(paren + 2));
  std::string field;
  double ticks = 0.0;
  for (int i = 3; i <= 15 && fields >> field; ++i)
    if (i >= 14) ticks += std::stod(field);
  return ticks / static_cast<double>(::sysconf(_SC_CLK_TCK));
}

RssSampler::RssSampler(int pid, std::chrono::milliseconds every, Failures& failures)
    : pid_(pid), every_(every), failures_(failures) {}

RssSampler::~RssSampler() { stop(); }

void RssSampler::start() {
  start_ = std::chrono::steady_clock::now();
  sample(0.0);
  thread_ = std::thread([this] {
    std::unique_lock lock(mutex_);
    for (auto next = start_ + every_;; next += every_) {
      // The period is the workload's sampling rate; stop() only cuts the wait short.
      if (stop_cv_.wait_until(lock, next, [&] { return stopping_; })) return;
      lock.unlock();
      sample(std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count());
      lock.lock();
    }
  });
}

void RssSampler::stop() {
  {
    std::lock_guard lock(mutex_);
    if (stopping_) return;
    stopping_ = true;
  }
  stop_cv_.notify_all();
  if (thread_.joinable()) thread_.join();
  sample(std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count());
}

void RssSampler::sample(double seconds) {
  const std::uint64_t bytes = resident_bytes(pid_);
  std::lock_guard lock(mutex_);
  if (bytes == 0) {
    if (!gone_reported_) failures_.add("the server process is gone (no VmRSS in /proc/" + std::to_string(pid_) + "/status)");
    gone_reported_ = true;
    return;
  }
  samples_.push_back({seconds, bytes});
}

std::vector<RssSample> RssSampler::samples() const {
  std::lock_guard lock(mutex_);
  return samples_;
}

std::uint64_t RssSampler::latest_bytes() const {
  std::lock_guard lock(mutex_);
  return samples_.empty() ? 0 : samples_.back().bytes;
}

MemoryVerdict judge_memory(const std::vector<RssSample>& samples, double warmup_seconds) {
  MemoryVerdict v;
  v.warmup_seconds = warmup_seconds;
  if (samples.empty()) return v;
  v.end = samples.back().bytes;
  // The baseline: the first sample at or after the end of warm-up.
  const auto base = std::find_if(samples.begin(), samples.end(), [&](const RssSample& s) { return s.seconds >= warmup_seconds; });
  // Judged only with a later sample to compare it with.
  if (base == samples.end() || base + 1 == samples.end()) {
    v.warmup_end = base == samples.end() ? 0 : base->bytes;
    for (const RssSample& s : samples) v.max = std::max(v.max, s.bytes);
    return v;
  }
  v.judged = true;
  v.warmup_end = base->bytes;
  for (auto it = base; it != samples.end(); ++it) v.max = std::max(v.max, it->bytes);
  const double b = static_cast<double>(v.warmup_end);
  v.growth = (static_cast<double>(v.end) - b) / b;
  v.max_growth = (static_cast<double>(v.max) - b) / b;
  return v;
}

}  // namespace filigree::soak
