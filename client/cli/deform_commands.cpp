// `filigree deform` (one pose) and `filigree animate` (a procedural motion).

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <optional>
#include <string>
#include <thread>

#include <CLI/CLI.hpp>

#include "cli/commands.h"
#include "hierarchy/hierarchy.h"
#include "hierarchy/hierarchy_file.h"
#include "mesh/gltf_io.h"
#include "mesh/mesh_io.h"
#include "runtime/deformer.h"
#include "runtime/pose_io.h"
#include "runtime/procedural_motion.h"
#include "skinning/animation_clip.h"
#include "skinning/rig_file.h"
#include "skinning/skinning.h"

namespace filigree::cli {
namespace {

// A cut that adapts over frames needs frames of the same pose to settle
// (FrameStats::cut_converged); deform runs at most this many.
constexpr int kSettleFrames = 2000;

struct RuntimeArgs {
  std::string hierarchy, output, threshold = "default", rotation = "best-fit", terms = "edge";
  int threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  int iterations = 0;
  double regions_budget_ms = 0.0;
};

struct DeformArgs : RuntimeArgs {
  std::string pose;
  bool stats = false;
};

struct AnimateArgs : RuntimeArgs {
  std::string motion = "bend", clip, rig, skinning = "linear";
  int frames = 30;
  double fps = 30.0;
};

DeformerOptions options_of(const RuntimeArgs& a) {
  DeformerOptions o;
  if (a.threshold == "inf" || a.threshold == "infinity") {
    o.threshold = DeformerOptions::kInfinity;
  } else if (a.threshold != "default") {
    std::size_t used = 0;
    try {
      o.threshold = std::stod(a.threshold, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used != a.threshold.size() || !(o.threshold >= 0.0))
      throw std::invalid_argument("--threshold takes a number ≥ 0, 'inf' or 'default', not '" + a.threshold + "'");
  }
  if (a.rotation == "best-fit") {
    o.rotation = RotationMethod::kBestFit;
  } else if (a.rotation == "local-frame") {
    o.rotation = RotationMethod::kLocalFrame;
  } else {
    throw std::invalid_argument("--rotation takes best-fit or local-frame, not '" + a.rotation + "'");
  }
  o.threads = a.threads;
  if (a.terms == "edge") {
    o.region_terms = RegionTerms::kEdgeRotations;
  } else if (a.terms == "vertex") {
    o.region_terms = RegionTerms::kVertexRotations;
  } else {
    throw std::invalid_argument("--terms takes edge or vertex, not '" + a.terms + "'");
  }
  o.local_global_iterations = a.iterations;
  o.regions_budget_ms = a.regions_budget_ms;
  return o;
}

void print_stats(const FrameStats& s, int frames) {
  std::printf("{\"frames_run\": %d, \"cut_converged\": %s, \"cut_nodes\": %zu, \"cut_vertices\": %zu, \"regions\": %zu, \"largest_region\": %zu, "
              "\"region_vertices\": %zu, \"threshold\": %.9g, \"performance_estimate\": %.9g, \"factorizations\": %zu, "
              "\"rotations_ms\": %.3f, \"cut_update_ms\": %.3f, \"recover_ms\": %.3f, \"regions_ms\": %.3f, \"total_ms\": %.3f}\n",
              frames, s.cut_converged ? "true" : "false", s.cut_nodes, s.cut_vertices, s.regions, s.region_sizes.empty() ? 0 : s.region_sizes.front(),
              s.region_vertices, std::isinf(s.threshold) ? 1e308 : s.threshold, s.performance_estimate, s.factorizations,
              s.rotations_ms, s.cut_update_ms, s.recover_ms, s.regions_ms, s.total_ms);
}

void add_runtime_options(CLI::App* cmd, RuntimeArgs& a) {
  cmd->add_option("hierarchy", a.hierarchy, "Hierarchy file (.fgh)")->required()->check(CLI::ExistingFile);
  cmd->add_option("-o,--output", a.output, "Output mesh")->required();
  cmd->add_option("--threshold", a.threshold, "Performance threshold T: a number, 0 (direct recovery only) or inf (whole-mesh optimisation)");
  cmd->add_option("--rotation", a.rotation, "Base rotations: best-fit (default) or local-frame");
  cmd->add_option("--terms", a.terms,
                  "How optimisation rotates the rest geometry: edge (default; each edge by its ends' mean rotation) or "
                  "vertex (each differential coordinate by its vertex's rotation, the thesis' form)");
  cmd->add_option("--iterations", a.iterations, "Local-global (as-rigid-as-possible) iterations; each lowers the energy or leaves it")
      ->check(CLI::Range(0, 100));
  cmd->add_option("--regions-budget-ms", a.regions_budget_ms,
                  "A time budget for each frame's region optimisation, in ms, instead of a fixed --threshold: T follows it "
                  "frame by frame (starting at --threshold, or 1e4)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--threads", a.threads, "Worker threads")->check(CLI::Range(1, 256));
}

void deform(const DeformArgs& a) {
  const Hierarchy h = load_hierarchy(a.hierarchy);
  const Pose pose = read_pose(a.pose, h.base_vertices.size());
  Deformer deformer(h, options_of(a));
  DeformResult r = deformer.deform(pose);
  int frames = 1;
  while (!r.stats.cut_converged && frames < kSettleFrames) r = deformer.deform(pose), ++frames;
  if (!r.stats.cut_converged)
    std::fprintf(stderr, "warning: the cut did not settle within %d frames of this pose; the result is that of the last "
                         "(a larger or smaller --threshold may settle)\n", kSettleFrames);
  TriMesh out = h.original_mesh();
  out.positions = std::move(r.positions);
  write_mesh(out, a.output);
  std::fprintf(stderr, "wrote %s: %zu vertices, %zu faces (input vertex and face order)\n", a.output.c_str(),
               out.vertex_count(), out.face_count());
  if (a.stats) print_stats(r.stats, frames);
}

// The base pose of frame f: the procedural motion, or the clip sampled
// evenly over its duration and skinned.
class BaseMotion {
 public:
  BaseMotion(const AnimateArgs& a, const Hierarchy& h) : base_rest_(h.base_mesh().positions) {
    if (a.clip.empty()) {
      const auto motion = parse_motion(a.motion);
      if (!motion) throw std::invalid_argument("--motion takes bend, twist, twist360, wave, bump or fold, not '" + a.motion + "'");
      motion_ = *motion;
      return;
    }
    const std::filesystem::path rig_path =
        a.rig.empty() ? std::filesystem::path(a.hierarchy).replace_extension(".rig") : std::filesystem::path(a.rig);
    if (!std::filesystem::exists(rig_path))
      throw std::invalid_argument(rig_path.string() + " does not exist: --clip needs the rig `filigree preprocess` writes for a skinned glTF");
    Rig full = load_rig(rig_path);
    if (full.vertex_count() != h.vertex_count())
      throw std::invalid_argument(rig_path.string() + " is the rig of another mesh (" + std::to_string(full.vertex_count()) +
                                  " vertices, the hierarchy has " + std::to_string(h.vertex_count()) + ")");
    rig_ = full.restricted_to(h.base_vertices);
    clip_ = rig_->clip(a.clip);
    if (!clip_) {
      std::string names;
      for (const AnimationClip& c : rig_->clips) names += (names.empty() ? "" : ", ") + c.name;
      throw std::invalid_argument("no clip '" + a.clip + "' (the rig has: " + (names.empty() ? "none" : names) + ")");
    }
    if (a.skinning == "dual-quaternion") method_ = SkinningMethod::kDualQuaternion;
    else if (a.skinning != "linear") throw std::invalid_argument("--skinning takes linear or dual-quaternion, not '" + a.skinning + "'");
  }

  Pose at(int frame, int frames) const {
    if (!clip_) {
      // One back-and-forth of the motion over the requested frames.
      const double phase = frames > 1 ? std::sin(M_PI * frame / (frames - 1)) : 1.0;
      return procedural_pose(base_rest_, motion_, phase);
    }
    SkeletonPose pose = SkeletonPose::rest(*rig_);
    sample_clip(*clip_, frames > 1 ? clip_->duration() * frame / (frames - 1) : 0.0, pose.local);
    Pose out;
    out.positions.resize(rig_->vertex_count());
    skin(*rig_, model_transforms(*rig_, pose), method_, out.positions);
    return out;
  }

  std::string name(const AnimateArgs& a) const { return clip_ ? "clip " + a.clip : a.motion; }

 private:
  std::vector<Vec3> base_rest_;
  Motion motion_{};
  std::optional<Rig> rig_;
  const AnimationClip* clip_ = nullptr;
  SkinningMethod method_ = SkinningMethod::kLinearBlend;
};

void animate(const AnimateArgs& a) {
  const Hierarchy h = load_hierarchy(a.hierarchy);
  const BaseMotion motion(a, h);
  Deformer deformer(h, options_of(a));
  std::vector<std::vector<Vec3>> frames;
  double total_ms = 0.0;
  const std::filesystem::path out(a.output);
  const bool glb = out.extension() == ".glb";
  for (int f = 0; f < a.frames; ++f) {
    DeformResult r = deformer.deform(motion.at(f, a.frames));
    total_ms += r.stats.total_ms;
    if (glb) {
      frames.push_back(std::move(r.positions));
    } else {
      // Any other extension: a sequence of files name_0000.ext, name_0001.ext, …
      char suffix[16];
      std::snprintf(suffix, sizeof suffix, "_%04d", f);
      TriMesh frame = h.original_mesh();
      frame.positions = std::move(r.positions);
      write_mesh(frame, out.parent_path() / (out.stem().string() + suffix + out.extension().string()));
    }
  }
  if (glb) write_glb_animation(h.original_mesh(), frames, a.fps, out);
  std::printf("%s: %d frames of '%s', %.2f ms per frame on average (%zu vertices)\n", a.output.c_str(), a.frames,
              motion.name(a).c_str(), total_ms / std::max(a.frames, 1), h.vertex_count());
}

}  // namespace

void add_deform_commands(CLI::App& app) {
  auto d = std::make_shared<DeformArgs>();
  CLI::App* deform_cmd = app.add_subcommand("deform", "Deform the detailed mesh from a pose of the base mesh");
  add_runtime_options(deform_cmd, *d);
  deform_cmd->add_option("--pose", d->pose, "Pose: .pose (float32 m×3, base order) or a posed base mesh (.obj …)")
      ->required()
      ->check(CLI::ExistingFile);
  deform_cmd->add_flag("--stats", d->stats, "Print the frame statistics as JSON on stdout");
  deform_cmd->callback([d] { deform(*d); });

  auto an = std::make_shared<AnimateArgs>();
  CLI::App* animate_cmd = app.add_subcommand("animate", "Deform along a procedural base motion; .glb: one morph target per frame, else a file per frame");
  add_runtime_options(animate_cmd, *an);
  animate_cmd->add_option("--motion", an->motion, "bend, twist, twist360, wave, bump or fold");
  animate_cmd->add_option("--frames", an->frames, "Number of frames")->check(CLI::Range(1, 100000));
  animate_cmd->add_option("--fps", an->fps, "Frame rate of the glTF animation")->check(CLI::PositiveNumber);
  animate_cmd->add_option("--clip", an->clip, "Play this animation clip of a skinned input instead of --motion (needs H.rig from `preprocess`)");
  animate_cmd->add_option("--rig", an->rig, "The rig file (default: the hierarchy's name with .rig)");
  animate_cmd->add_option("--skinning", an->skinning, "linear (default) or dual-quaternion");
  animate_cmd->callback([an] { animate(*an); });
}

}  // namespace filigree::cli
