// `filigree history`, `undo`, `redo`, `checkpoint`, `export-history`,
// `replay-history`: a session's edit history through filigree-server (the
// client library, filigree::client).

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "cli/channel_security.h"
#include "cli/commands.h"
#include "cli/rest_mesh.h"
#include "cli/session_token.h"
#include "filigree/client.h"
#include "mesh/gltf_io.h"
#include "mesh/tri_mesh.h"

namespace filigree::cli {
namespace {

constexpr const char* kDefaultServer = "127.0.0.1:50051";

struct SessionTarget {
  std::string session, token_file, server = kDefaultServer;
  std::string token() const { return read_session_token(token_file, "--token-file", "FILIGREE_TOKEN"); }
};

struct ListArgs : SessionTarget {
  std::uint32_t newest = 0;
};

struct UndoArgs : SessionTarget {
  std::string client;
  bool force = false;
};

struct CheckpointArgs : SessionTarget {
  std::string name, client = "filigree-cli";
  std::uint64_t id = 0;
};

struct RangeArgs : SessionTarget {
  std::uint64_t from = 0, to = 0;
};

struct ExportArgs : RangeArgs {
  std::string output;
  double fps = 24.0;
};

struct ReplayArgs : RangeArgs {
  std::string into, into_token_file;
};

const char* kind_name(v1::HistoryEntry::Kind kind) {
  switch (kind) {
    case v1::HistoryEntry::KIND_POSE: return "pose";
    case v1::HistoryEntry::KIND_HANDLES: return "handles";
    case v1::HistoryEntry::KIND_THRESHOLD: return "threshold";
    case v1::HistoryEntry::KIND_RESTORE: return "restore";
    case v1::HistoryEntry::KIND_UNDO: return "undo";
    case v1::HistoryEntry::KIND_REDO: return "redo";
    default: return "other";
  }
}

// "2026-11-28 05:51:50" (UTC) of Unix seconds.
std::string utc(double seconds) {
  const std::time_t t = static_cast<std::time_t>(seconds);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char text[32];
  std::strftime(text, sizeof text, "%Y-%m-%d %H:%M:%S", &tm);
  return text;
}

// "3 17 42": vertex ids separated by spaces.
template <class Vertices>
std::string vertex_list(const Vertices& vertices) {
  std::string out;
  for (const std::uint32_t v : vertices) {
    if (!out.empty()) out += ' ';
    out += std::to_string(v);
  }
  return out;
}

void print_checkpoints(const v1::History& h) {
  if (h.checkpoints().empty()) {
    std::printf("no checkpoints\n");
    return;
  }
  std::printf("%-6s %-24s %-16s %11s  %s\n", "ID", "NAME", "AUTHOR", "AFTER_ENTRY", "TIME (UTC)");
  for (const v1::Checkpoint& c : h.checkpoints())
    std::printf("%-6llu %-24s %-16s %11llu  %s\n", static_cast<unsigned long long>(c.id()), c.name().c_str(),
                c.author().c_str(), static_cast<unsigned long long>(c.after_entry()), utc(c.time()).c_str());
}

// ---------------------------------------------------------------- history

void history(const ListArgs& a) {
  Client client(a.server, channel_credentials());
  const v1::History h = client.history(a.session, a.token(), a.newest);
  if (h.entries().empty()) {
    std::printf("no history entries\n");
  } else {
    std::printf("%-6s %-16s %-10s %8s %-6s %-8s %s\n", "SEQ", "AUTHOR", "KIND", "VERTICES", "UNDONE", "TARGET",
                "TIME (UTC)");
    for (const v1::HistoryEntry& e : h.entries()) {
      const std::string target = e.target() != 0 ? std::to_string(e.target()) : "-";
      std::printf("%-6llu %-16s %-10s %8d %-6s %-8s %s\n", static_cast<unsigned long long>(e.seq()),
                  e.author().empty() ? "-" : e.author().c_str(), kind_name(e.kind()), e.base_vertices_size(),
                  e.undone() ? "yes" : "no", target.c_str(), utc(e.end_time()).c_str());
    }
  }
  if (h.first_seq() > 1)
    std::printf("entries before %llu were dropped to keep the history within its bounds\n",
                static_cast<unsigned long long>(h.first_seq()));
  print_checkpoints(h);
}

// ---------------------------------------------------------------- undo, redo, restore

void print_outcome(const char* verb, const EditOutcome& o) {
  std::printf("result: %s\nentry: %llu\nrecorded: %llu\naccepted_at_version: %llu\nmessage: %s\n",
              result_name(o.result), static_cast<unsigned long long>(o.entry),
              static_cast<unsigned long long>(o.recorded), static_cast<unsigned long long>(o.accepted_at_version),
              o.message.empty() ? verb : o.message.c_str());
  for (const EditConflict& c : o.conflicts)
    std::printf("conflict: %s entry %llu base vertices %s\n", c.author.c_str(), static_cast<unsigned long long>(c.entry),
                vertex_list(c.base_vertices).c_str());
}

void undo(const UndoArgs& a, bool redo) {
  Client client(a.server, channel_credentials());
  const EditOutcome o = redo ? client.redo(a.session, a.token(), a.client, a.force)
                             : client.undo(a.session, a.token(), a.client, a.force);
  print_outcome(redo ? "redo" : "undo", o);
}

// ---------------------------------------------------------------- checkpoints

void checkpoint_create(const CheckpointArgs& a) {
  Client client(a.server, channel_credentials());
  const v1::Checkpoint c = client.create_checkpoint(a.session, a.token(), a.name, a.client);
  std::printf("checkpoint: %llu\nname: %s\nafter_entry: %llu\nversion: %llu\n", static_cast<unsigned long long>(c.id()),
              c.name().c_str(), static_cast<unsigned long long>(c.after_entry()),
              static_cast<unsigned long long>(c.version()));
}

void checkpoint_restore(const CheckpointArgs& a) {
  Client client(a.server, channel_credentials());
  print_outcome("restore", client.restore_checkpoint(a.session, a.token(), a.id, a.client));
}

void checkpoint_diff(const CheckpointArgs& a) {
  Client client(a.server, channel_credentials());
  const v1::CheckpointDiff d = client.diff_checkpoint(a.session, a.token(), a.id);
  std::printf("checkpoint: %llu\nversion: %llu\nvertices_differing: %d\nmax_distance: %.6g\nrms_distance: %.6g\n"
              "threshold_differs: %s\n",
              static_cast<unsigned long long>(d.checkpoint()), static_cast<unsigned long long>(d.version()),
              d.base_vertices_size(), d.max_distance(), d.rms_distance(), d.threshold_differs() ? "yes" : "no");
  if (!d.base_vertices().empty()) std::printf("base_vertices: %s\n", vertex_list(d.base_vertices()).c_str());
}

void checkpoint_list(const SessionTarget& a) {
  Client client(a.server, channel_credentials());
  print_checkpoints(client.history(a.session, a.token()));
}

// ---------------------------------------------------------------- export-history

std::string lower_extension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

void export_history(const ExportArgs& a) {
  if (lower_extension(a.output) != ".glb")
    throw std::invalid_argument("-o takes a .glb file (an animation of morph targets), not " + a.output);
  Client client(a.server, channel_credentials());
  const std::string token = a.token();
  const SessionMesh session = client.join(a.session, token);
  auto exported = client.export_history(a.session, token, session.rest_positions, a.from, a.to);
  std::vector<std::vector<Vec3>> frames;
  std::uint64_t first = 0, last = 0;
  while (auto state = exported->read()) {
    if (frames.empty()) first = state->entry;
    last = state->entry;
    std::printf("entry %llu  %s  version %llu  max_error %.3g\n", static_cast<unsigned long long>(state->entry),
                state->author.empty() ? "-" : state->author.c_str(), static_cast<unsigned long long>(state->version),
                state->max_error);
    frames.push_back(points_from_xyz(state->positions));
  }
  throw_if_error(exported->finish());
  if (frames.empty()) throw std::runtime_error("the history holds no entries in that range: nothing to write");
  // The rest mesh with one morph target per state (its decoded deltas), and
  // an animation that shows state k alone at time k / fps.
  write_glb_animation(rest_mesh(session), frames, a.fps, a.output);
  std::fprintf(stderr, "wrote %s: %zu states (entries %llu to %llu) of %zu vertices at %g fps\n", a.output.c_str(),
               frames.size(), static_cast<unsigned long long>(first), static_cast<unsigned long long>(last),
               session.vertex_count(), a.fps);
}

// ---------------------------------------------------------------- replay-history

void replay_history(const ReplayArgs& a) {
  if (a.into == a.session) throw std::invalid_argument("--into names the session replayed: give another one");
  Client client(a.server, channel_credentials());
  const std::string token = a.token();
  const std::string into_token = read_session_token(a.into_token_file, "--into-token-file", "FILIGREE_INTO_TOKEN");
  const SessionMesh source = client.join(a.session, token);
  const SessionMesh target = client.join(a.into, into_token);
  if (source.base_vertex_count() != target.base_vertex_count())
    throw std::runtime_error("session " + a.into + "'s base has " + std::to_string(target.base_vertex_count()) +
                             " vertices, " + a.session + "'s " + std::to_string(source.base_vertex_count()) +
                             ": a pose of one is no pose of the other");
  // Each state is its own gesture in the other session (one entry, undone
  // as one, even for states of one author less than 0.5 s apart): ids of
  // this run, unlike any the other session's authors have open.
  std::random_device device;
  const std::uint64_t run = (std::uint64_t{device()} << 32 | device()) & ~std::uint64_t{0xFFFFFF};
  auto exported = client.export_history(a.session, token, source.rest_positions, a.from, a.to);
  std::vector<float> previous;
  std::size_t submitted = 0, unchanged = 0;
  while (auto state = exported->read()) {
    if (state->base_pose == previous) {  // a threshold's entry, or an undo that changed nothing
      ++unchanged;
      continue;
    }
    const std::string author = state->author.empty() ? "replay" : state->author;
    const std::uint64_t version =
        client.submit_pose(a.into, into_token, author, state->base_pose, run | (state->entry & 0xFFFFFF));
    std::printf("entry %llu  %s  accepted_at_version %llu\n", static_cast<unsigned long long>(state->entry),
                author.c_str(), static_cast<unsigned long long>(version));
    previous = std::move(state->base_pose);
    ++submitted;
  }
  throw_if_error(exported->finish());
  std::fprintf(stderr, "replayed %zu poses into %s (%zu states with an unchanged pose skipped)\n", submitted,
               a.into.c_str(), unchanged);
}

// ---------------------------------------------------------------- options

void add_target(CLI::App* cmd, SessionTarget& a, const char* token_help) {
  cmd->add_option("session,--session", a.session, "Session id")->required();
  cmd->add_option("--token-file", a.token_file, token_help)->check(CLI::ExistingFile);
  cmd->add_option("--server", a.server, "Server address HOST:PORT");
}

constexpr const char* kViewerToken = "File whose first line is a token of the session (default: $FILIGREE_TOKEN)";
constexpr const char* kEditorToken =
    "File whose first line is the session's editor token (default: $FILIGREE_TOKEN)";

}  // namespace

void add_history_commands(CLI::App& app) {
  auto l = std::make_shared<ListArgs>();
  CLI::App* hi = app.add_subcommand("history", "List a session's history (oldest first) and its checkpoints");
  add_target(hi, *l, kViewerToken);
  hi->add_option("--newest", l->newest, "Only the newest N entries");
  hi->callback([l] { history(*l); });

  for (const bool redo : {false, true}) {
    auto u = std::make_shared<UndoArgs>();
    CLI::App* cmd = app.add_subcommand(redo ? "redo" : "undo",
                                       redo ? "Redo an author's latest undone change"
                                            : "Undo an author's latest change (others' later work on the same "
                                              "vertices stays, unless --force)");
    add_target(cmd, *u, kEditorToken);
    cmd->add_option("--client", u->client, "Whose change: the author's client name")->required();
    cmd->add_flag("--force", u->force, "Also restore the vertices others changed since (their change is overwritten there)");
    cmd->callback([u, redo] { undo(*u, redo); });
  }

  CLI::App* cp = app.add_subcommand("checkpoint", "Name the current pose, go back to a checkpoint, compare with one");
  cp->require_subcommand(1);
  auto c = std::make_shared<CheckpointArgs>();
  CLI::App* create = cp->add_subcommand("create", "Name the current pose and threshold");
  add_target(create, *c, kEditorToken);
  create->add_option("name,--name", c->name, "The checkpoint's name (1 to 200 characters)")->required();
  create->add_option("--client", c->client, "Its author's client name");
  create->callback([c] { checkpoint_create(*c); });
  auto r = std::make_shared<CheckpointArgs>();
  CLI::App* restore = cp->add_subcommand("restore", "Go back to a checkpoint (a history entry of --client: undo takes it back)");
  add_target(restore, *r, kEditorToken);
  restore->add_option("id,--id", r->id, "The checkpoint's id (filigree checkpoint list)")->required();
  restore->add_option("--client", r->client, "Whose entry the restore is");
  restore->callback([r] { checkpoint_restore(*r); });
  auto d = std::make_shared<CheckpointArgs>();
  CLI::App* diff = cp->add_subcommand("diff", "Compare the current pose with a checkpoint's");
  add_target(diff, *d, kViewerToken);
  diff->add_option("id,--id", d->id, "The checkpoint's id")->required();
  diff->callback([d] { checkpoint_diff(*d); });
  auto ls = std::make_shared<SessionTarget>();
  CLI::App* list = cp->add_subcommand("list", "List the checkpoints");
  add_target(list, *ls, kViewerToken);
  list->callback([ls] { checkpoint_list(*ls); });

  auto e = std::make_shared<ExportArgs>();
  CLI::App* ex = app.add_subcommand(
      "export-history", "Write the state after each history entry as a glTF animation: the rest mesh with one morph "
                        "target per state, shown one at a time (state k at time k / fps)");
  add_target(ex, *e, kViewerToken);
  ex->add_option("--from", e->from, "The first entry (default: the oldest kept)");
  ex->add_option("--to", e->to, "The last entry (default: the newest)");
  ex->add_option("--fps", e->fps, "States per second of the animation")->check(CLI::PositiveNumber);
  ex->add_option("-o,--output", e->output, "The .glb file to write")->required();
  ex->callback([e] { export_history(*e); });

  auto p = std::make_shared<ReplayArgs>();
  CLI::App* rp = app.add_subcommand(
      "replay-history", "Submit the base pose after each history entry of a session to another session of the same "
                        "base, as a pose of the entry's author (states whose pose did not change are skipped)");
  add_target(rp, *p, kViewerToken);
  rp->add_option("--into", p->into, "The session to replay into")->required();
  rp->add_option("--into-token-file", p->into_token_file,
                 "File whose first line is that session's editor token (default: $FILIGREE_INTO_TOKEN)")
      ->check(CLI::ExistingFile);
  rp->add_option("--from", p->from, "The first entry (default: the oldest kept)");
  rp->add_option("--to", p->to, "The last entry (default: the newest)");
  rp->callback([p] { replay_history(*p); });
}

}  // namespace filigree::cli
