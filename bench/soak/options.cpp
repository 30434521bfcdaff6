#include "bench/soak/options.h"

#include <stdexcept>
#include <string_view>

namespace filigree::soak {

std::string usage() {
  return "usage: filigree_soak [--seconds N] [--sessions N] [--server PATH] [--rate-hz HZ]\n"
         "                     [--memory-check=on|off] [--crash-cycles N] [--upload-mib N]\n"
         "  --seconds N          how long to drive (default 600)\n"
         "  --sessions N         sessions, each with a driver and 3 watchers (default 16)\n"
         "  --server PATH        filigree-server binary (default: the one built beside this)\n"
         "  --rate-hz HZ         poses per second per driver (default 30)\n"
         "  --memory-check=off   do not judge the server's memory growth (for runs too short\n"
         "                       to judge it); every other criterion still applies\n"
         "  --crash-cycles N     then N SIGKILL/restart cycles under load (default 3; 0: none)\n"
         "  --upload-mib N       then 8 concurrent uploads of N MiB each under --max-memory\n"
         "                       of 4·N MiB (default 64; 0: none)\n";
}

namespace {

double number(std::string_view flag, const std::string& value) {
  try {
    std::size_t used = 0;
    const double v = std::stod(value, &used);
    if (used == value.size() && v > 0.0) return v;
  } catch (const std::exception&) {
  }
  throw std::invalid_argument(std::string(flag) + " wants a positive number, not '" + value + "'");
}

}  // namespace

Options parse_options(int argc, char** argv) {
  Options o;
#ifdef FILIGREE_SERVER_BINARY
  o.server = FILIGREE_SERVER_BINARY;
#endif
  for (int i = 1; i < argc; ++i) {
    std::string arg = argv[i], value;
    // Both "--flag value" and "--flag=value".
    if (const auto eq = arg.find('='); arg.rfind("--", 0) == 0 && eq != std::string::npos) {
      value = arg.substr(eq + 1);
      arg = arg.substr(0, eq);
    } else if (arg != "--help" && arg != "-h" && arg != "--memory-check") {
      if (i + 1 >= argc) throw std::invalid_argument(arg + " wants a value");
      value = argv[++i];
    }
    if (arg == "--help" || arg == "-h") throw std::invalid_argument("");
    if (arg == "--seconds") {
      o.seconds = number(arg, value);
    } else if (arg == "--sessions") {
      o.sessions = static_cast<int>(number(arg, value));
      if (o.sessions < 1) throw std::invalid_argument("--sessions wants at least 1");
    } else if (arg == "--server") {
      o.server = value;
    } else if (arg == "--crash-cycles") {
      o.crash_cycles = static_cast<int>(number(arg, value));
    } else if (arg == "--upload-mib") {
      o.upload_mib = static_cast<int>(number(arg, value));
    } else if (arg == "--rate-hz") {
      o.rate_hz = number(arg, value);
    } else if (arg == "--memory-check") {
      if (value == "on" || value.empty()) {
        o.memory_check = true;
      } else if (value == "off") {
        o.memory_check = false;
      } else {
        throw std::invalid_argument("--memory-check is on or off, not '" + value + "'");
      }
    } else {
      throw std::invalid_argument("unknown argument '" + arg + "'");
    }
  }
  if (o.server.empty()) throw std::invalid_argument("--server PATH is needed");
  return o;
}

}  // namespace filigree::soak
