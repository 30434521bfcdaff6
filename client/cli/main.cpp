// `filigree`: the command-line tool (preprocess, inspect, export-base, export-cut, deform,
// animate, compare; upload, drive, watch, sessions as a client of filigree-server).

#include <cstdio>
#include <exception>

#include <CLI/CLI.hpp>

#include "cli/channel_security.h"
#include "cli/commands.h"

int main(int argc, char** argv) {
  CLI::App app{"Filigree: detail-preserving deformation from a small base mesh"};
  app.require_subcommand(1);
  filigree::cli::add_channel_security_options(app);
  filigree::cli::add_preprocess_command(app);
  filigree::cli::add_inspect_command(app);
  filigree::cli::add_export_commands(app);
  filigree::cli::add_deform_commands(app);
  filigree::cli::add_compare_command(app);
  filigree::cli::add_service_commands(app);
  filigree::cli::add_history_commands(app);
  filigree::cli::add_rig_command(app);
  filigree::cli::add_health_command(app);
  filigree::cli::add_api_key_command(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const std::exception& e) {
    // Every command reports failures as exceptions with a message for a person.
    std::fprintf(stderr, "filigree: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
