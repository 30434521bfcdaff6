#pragma once
// The soak's upload phase: many large uploads at once against a server with
// --max-memory. Each declares and sends `upload_mib` MiB (comment lines, then
// a small mesh: cheap to parse, so the bytes are what weighs). Checks: every
// upload is either created or refused RESOURCE_EXHAUSTED at its start; at
// least one is refused (the limit bites); the server's resident memory,
// sampled throughout, stays within the limit plus what parsing one upload
// at a time may add (twice its size).

#include <cstdint>
#include <string>

#include "bench/soak/failures.h"

namespace filigree::soak {

struct UploadPressureSummary {
  int uploads = 0, created = 0, refused = 0;
  std::uint64_t limit_bytes = 0, peak_rss_bytes = 0;
};

UploadPressureSummary run_upload_pressure(const std::string& server_binary, int uploads, int upload_mib, int max_memory_mib,
                                          Failures& failures);

}  // namespace filigree::soak
