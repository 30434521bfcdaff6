#pragma once
// The `filigree` subcommands; each registers itself on the app.

namespace CLI {
class App;
}

namespace filigree::cli {

void add_preprocess_command(CLI::App& app);
void add_inspect_command(CLI::App& app);
void add_export_commands(CLI::App& app);  // export-base, export-cut
void add_compare_command(CLI::App& app);
void add_deform_commands(CLI::App& app);  // deform, animate
void add_service_commands(CLI::App& app);
void add_history_commands(CLI::App& app);  // history, undo, redo, checkpoint, export-history, replay-history
void add_rig_command(CLI::App& app);
void add_api_key_command(CLI::App& app);  // api-key: a key for filigree-server --api-keys     // rig: an automatic skinned glTF
void add_health_command(CLI::App& app);  // health: the server's gRPC health service  // upload, drive, watch, sessions: clients of filigree-server

}  // namespace filigree::cli
