// psc_demo: soft-body scenes simulated with the particle sensors and with Bullet's default
// soft-soft pipeline side by side, measured against an exact ground truth. Without arguments it
// runs the default suite and writes results/ (see suite.h).
#include "mesh_file.h"
#include "psc/bullet/memory.h"
#include "psc/error.h"
#include "scenes.h"
#include "sensor_pipeline.h"
#include "suite.h"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <cstdio>
#include <iostream>
#include <limits>
#include <sstream>

using namespace psc::demo;

namespace {

/// Comma-separated positive whole numbers up to `max`; `option` names the option in the message.
std::vector<std::size_t> parseValues(const std::vector<std::string>& tokens, const std::string& option,
                                     unsigned long long max = std::numeric_limits<std::size_t>::max()) {
  std::vector<std::size_t> values;
  for (const std::string& token : tokens) {
    std::stringstream in(token);
    for (std::string item; std::getline(in, item, ',');) {
      if (item.empty()) continue;
      std::size_t pos = 0;
      unsigned long long v = 0;
      try {
        v = std::stoull(item, &pos);
      } catch (const std::exception&) {
        pos = 0;
      }
      const bool digits = item.find_first_not_of("0123456789") == std::string::npos;  // stoull takes "-3", " 3"
      if (!digits || pos != item.size() || v == 0 || v > max)
        throw psc::Error(psc::ErrorCode::InvalidArgument,
                         option + ": '" + item + "' is not a positive whole number" +
                             (digits && v > max ? " up to " + std::to_string(max) : ""));
      values.push_back(static_cast<std::size_t>(v));
    }
  }
  return values;
}

void listScenes() {
  std::printf("%-4s %-12s %-7s %-6s %-6s %s\n", "#", "name", "bodies", "steps", "res", "what");
  for (const SceneInfo& s : sceneCatalog())
    std::printf("%-4s %-12s %-7s %-6zu %-6zu %s\n", s.number.c_str(), s.name.c_str(),
                (s.takes_body_count ? std::to_string(s.default_bodies) + "*" : std::to_string(s.default_bodies)).c_str(),
                s.default_steps, s.default_resolution, s.summary.c_str());
  std::printf("(* = --bodies applies)\n");
}

}  // namespace

int main(int argc, char** argv) {
  if (argc == 1) {
    psc::bullet::alignLargeBulletBlocks();
    std::cerr << "psc_demo: no arguments: running the default suite (every scene, all three pipelines, both ground truths; "
                 "results/ gets demo.json, demo.csv and plots/). psc_demo --help lists the options.\n";
    return runSuite(defaultSuite(), defaultSuiteOptions(), std::cout, std::cerr);
  }

  CLI::App app{"psc_demo: particle-sensor soft-soft collision vs Bullet's VF_SS default, side by side.\n"
               "Without arguments: the default suite, writing results/."};
  std::vector<std::string> scenes;
  SceneParams params;
  std::size_t steps = 0, warmup = 0, frame_every = 1;
  std::string pipeline = "both", flagging = "default", truth = "both", exact = "bullet", motion_bound = "radius", contacts = "all", json, csv, frames, plot_dir;
  std::vector<std::string> sweep, bullet_clusters;
  bool list = false, no_penetration = false, self_collision = false, refit_in_step = false, runaway_fallback = false;
  app.add_option("--scene", scenes, "scene name or number, repeatable, or 'all' (default: all; see --list-scenes)");
  app.add_option("--resolution", params.resolution, "vertices per body (default: the scene's, 1000; cloth_fold 2000)")->check(CLI::Range(14, 10000000));
  app.add_option("--bodies", params.bodies, "body count, for scenes that take one (default: the scene's)")
      ->check(CLI::Range(1, 100000));
  app.add_option("--steps", steps, "simulation steps (default: the scene's)")->check(CLI::Range(1, 10000000));
  app.add_option("--seed", params.seed, "placement seed (default 1)");
  app.add_option("--scale", params.scale,
                 "multiply every length by this (default 1; 1e-6 to 1e6); Bullet's exact test skips triangles of area "
                 "below 1.7e-4 units^2, so very fine meshes need a larger scale")
      ->check(CLI::PositiveNumber);
  app.add_option("--pipeline", pipeline,
                 "sensors, bounds (sensors with the sensor stage off: boxes only), bullet, both (sensors and "
                 "bullet; the default) or all (all three)")
      ->check(CLI::IsMember({"sensors", "bounds", "bullet", "both", "all"}));
  app.add_option("--flagging", flagging,
                 "the sensors run's flagging: default (Flagging::SensorsAndBounds) or thesis (Flagging::Sensors, "
                 "the thesis's flag-only mode)")
      ->check(CLI::IsMember({"default", "thesis"}));
  app.add_option("--exact", exact,
                 "the sensors' exact test: bullet (Bullet's CollideVF_SS), robust (also small triangles, any "
                 "scale) or continuous (robust + crossings during the step); default bullet. Bullet's own "
                 "pipeline always uses Bullet's test")
      ->check(CLI::IsMember({"bullet", "robust", "continuous"}));
  app.add_option("--motion-bound", motion_bound,
                 "our pipelines' motion bound: radius (the default: every pair inside Bullet's radius margins "
                 "+ 2|dx|), ahead (of those, the pairs within the margins or that the node and the face head "
                 "into during the next step) or swept (the pairs that meet within the margins during the step, "
                 "the node's path against the face's swept volume: with --exact continuous its crossing test "
                 "then also sees a slow node that a fast face sweeps over, but pairs in Bullet's radius that "
                 "do not meet get no contact)")
      ->check(CLI::IsMember({"ahead", "radius", "swept"}));
  app.add_option("--truth", truth, "ground truth: none, strict, full or both (default both)")
      ->check(CLI::IsMember({"none", "strict", "full", "both"}));
  app.add_option("--mesh", params.mesh_file, "OBJ/OFF/PLY/STL file for scene 8 ('mesh'); alone it selects scene 8");
  app.add_option("--sweep", sweep, "resolution|bodies followed by values, e.g. --sweep resolution 500,1000,2000")
      ->expected(2, 1000)
      ->type_name("KIND VALUES");
  app.add_option("--bullet-clusters", bullet_clusters,
                 "Bullet's cluster self-collision, to compare with --self-collision. After the runs of "
                 "--pipeline (whichever it is), two more Bullet runs per K, every body given "
                 "btSoftBody::generateClusters(K) and cluster collision instead of VF_SS: bullet_clK with "
                 "SDF_RS|CL_SS|CL_SELF as Bullet documents it (in Bullet 3.24 this matches no case of "
                 "defaultCollisionHandler: no cluster contact at all), and bullet_clK_direct with SDF_RS|CL_SS "
                 "and Bullet's cluster self-collision (CollideCL_SS on the body with itself) called in the "
                 "world's self pass. K: positive whole numbers (Bullet caps K at the body's node count). "
                 "Not in the plots or the B/ours ratios; best with --truth none (their contacts are "
                 "cluster joints, not vertex-face contacts)")
      ->type_name("K[,K...]")
      ->expected(1, 1000);
  app.add_option("--json", json, "write results as JSON");
  app.add_option("--csv", csv, "write results as CSV");
  app.add_option("--frames", frames, "write a VTK series per run into DIR (open the .pvd in ParaView)");
  app.add_option("--frame-every", frame_every, "with --frames: every n-th step (default 1)")->check(CLI::Range(1, 1000000));
  app.add_option("--plot", plot_dir, "write PNG plots into DIR (needs gnuplot)");
  app.add_option("--warmup", warmup, "steps left out of the timing means and medians (default min(10, max(1, steps/10)))");
  CLI::Option* self_flag = app.add_flag("--self-collision", self_collision,
               "self-collision on every body of our pipelines (Bullet's own has none), and the self truth "
               "(self_recall_strict) for every pipeline");
  bool no_self_rest_bound = false;
  app.add_flag("--no-self-rest-bound", no_self_rest_bound,
               "with --self-collision: our pipelines without the rest-shape bound (psc::SensorSettings::"
               "self_rest_bound off), its ablation: a body's chunk pairs with itself go by their boxes alone")
      ->needs(self_flag);
  app.add_flag("--refit-in-step", refit_in_step,
               "our pipelines refit every body in the sensor step (cold) instead of right after its "
               "predictMotion (psc::bullet::SoftBodySolver, the default here)");
  bool no_runaway_sharing = false;
  app.add_flag("--no-runaway-sharing", no_runaway_sharing,
               "our pipelines: Bullet's contact weights in a pair that runs away (without it, such a pair's "
               "contacts beyond the margins share one contact's weight per node: "
               "psc::bullet::Settings::runaway_sharing); with --crowded-band 0 too, Bullet's weights always");
  std::size_t crowded_band = psc::bullet::Settings{}.crowded_band;
  app.add_option("--crowded-band", crowded_band,
                 "our pipelines: a node with more than this many contacts beyond the "
                 "margins against one body shares one contact's weight among them, in any pair "
                 "(psc::bullet::Settings::crowded_band; default 32; 0: off)")
      ->check(CLI::NonNegativeNumber);
  app.add_flag("--runaway-fallback", runaway_fallback,
               "our pipelines with --exact bullet or robust and the radius bound: a body pair that runs away goes "
               "on the ahead bound until its bodies part (psc::bullet::Settings::runaway_fallback)");
  app.add_option("--contacts", contacts,
                 "our pipelines: all (every pair the exact test accepts, Bullet's model; default) or nearest (per node "
                 "and body it touches, the nearest face's contact: psc::bullet::Settings::contacts)")
      ->check(CLI::IsMember({"all", "nearest"}));
  bool default_alignment = false;
  app.add_flag("--bullet-default-alignment", default_alignment,
               "keep Bullet's own allocator for every pipeline: its large arrays then start 32 bytes into a cache "
               "line, and each node's m_x and m_q lie on two lines (without it, psc::bullet::alignLargeBulletBlocks "
               "is called before any body is made)");
  app.add_flag("--no-penetration", no_penetration, "skip the inside tests after each step");
  app.add_flag("--list-scenes", list, "list the scenes and exit");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  if (!default_alignment) psc::bullet::alignLargeBulletBlocks();
  if (list) {
    listScenes();
    return 0;
  }

  try {
    if (!params.mesh_file.empty()) {
      // Read it once up front: a bad file is reported before anything runs.
      MeshFileInfo info;
      const psc::TriMesh mesh = loadMeshFile(params.mesh_file, &info);
      std::cerr << "psc_demo: " << params.mesh_file << ": " << mesh.vertices.size() << " vertices, "
                << mesh.triangles.size() << " triangles from " << info.meshes << " mesh(es)\n";
      if (scenes.empty()) scenes.push_back("mesh");
    }
    if (scenes.empty() || std::find(scenes.begin(), scenes.end(), "all") != scenes.end()) {
      scenes.clear();
      for (const SceneInfo& s : sceneCatalog()) scenes.push_back(s.name);
    }
    for (const std::string& s : scenes)
      if (!findScene(s)) makeScene(s, params);  // throws the "unknown scene" message with the list

    SuiteOptions options;
    options.pipelines.clear();
    if (pipeline == "sensors" || pipeline == "both" || pipeline == "all") options.pipelines.push_back(Pipeline::Sensors);
    if (pipeline == "bounds" || pipeline == "all") options.pipelines.push_back(Pipeline::Bounds);
    if (pipeline == "bullet" || pipeline == "both" || pipeline == "all") options.pipelines.push_back(Pipeline::Bullet);
    if ((pipeline == "sensors" || pipeline == "bounds") && !SensorPipeline::available())
      throw psc::Error(psc::ErrorCode::InvalidArgument, "this psc_demo was built without psc::bullet: use --pipeline bullet");
    if (!SensorPipeline::available() && (pipeline == "both" || pipeline == "all")) {
      std::cerr << "psc_demo: warning: built without psc::bullet, running the Bullet pipeline only\n";
      options.pipelines = {Pipeline::Bullet};
    }
    if (flagging == "thesis" && std::find(options.pipelines.begin(), options.pipelines.end(), Pipeline::Sensors) ==
                                    options.pipelines.end())
      throw psc::Error(psc::ErrorCode::InvalidArgument,
                       "--flagging thesis sets the sensors run's flagging, but --pipeline " + pipeline + " has no sensors run");
    options.run.flagging = flagging == "thesis" ? FlaggingMode::Thesis : FlaggingMode::Default;
    options.run.truth = truth == "none"     ? TruthMode::None
                        : truth == "strict" ? TruthMode::Strict
                        : truth == "full"   ? TruthMode::Full
                                            : TruthMode::Both;
    options.run.penetration = !no_penetration;
    options.run.exact = exact;
    options.run.motion_bound = motion_bound;
    options.run.self_collision = self_collision;
    options.run.self_rest_bound = !no_self_rest_bound;
    options.run.refit_after_predict = !refit_in_step;
    options.run.runaway_fallback = runaway_fallback;
    options.run.runaway_sharing = !no_runaway_sharing;
    options.run.crowded_band = crowded_band;
    options.run.contacts = contacts;
    options.run.frames_dir = frames;
    options.run.frame_every = frame_every;
    options.run.warmup = warmup;
    options.json = json;
    options.csv = csv;
    options.plot_dir = plot_dir;
    if (!bullet_clusters.empty()) {
      for (std::size_t k : parseValues(bullet_clusters, "--bullet-clusters",
                                       static_cast<unsigned long long>(std::numeric_limits<int>::max())))
        options.bullet_clusters.push_back(static_cast<int>(k));
      if (options.bullet_clusters.empty())
        throw psc::Error(psc::ErrorCode::InvalidArgument, "--bullet-clusters: no cluster count given");
    }

    std::vector<Job> jobs;
    if (sweep.empty()) {
      for (const std::string& s : scenes) jobs.push_back({s, params, steps, "scenes"});
    } else {
      const std::string kind = sweep.front();
      if (kind != "resolution" && kind != "bodies")
        throw psc::Error(psc::ErrorCode::InvalidArgument, "--sweep: '" + kind + "' is neither 'resolution' nor 'bodies'");
      const std::vector<std::size_t> values = parseValues({sweep.begin() + 1, sweep.end()}, "--sweep");
      if (values.empty()) throw psc::Error(psc::ErrorCode::InvalidArgument, "--sweep " + kind + ": no values given");
      for (const std::string& s : scenes) {
        const SceneInfo* info = findScene(s);
        if (kind == "bodies" && !info->takes_body_count)
          throw psc::Error(psc::ErrorCode::InvalidArgument,
                           "--sweep bodies: scene '" + info->name + "' has a fixed body count (scenes that take one: "
                           "tori_pile, mixed_pile, mesh)");
        for (std::size_t v : values) {
          Job j{s, params, steps, "sweep_" + kind};
          (kind == "resolution" ? j.params.resolution : j.params.bodies) = v;
          if (kind == "resolution" && v < 14)
            throw psc::Error(psc::ErrorCode::InvalidArgument, "--sweep resolution: " + std::to_string(v) + " is below 14");
          jobs.push_back(j);
        }
      }
    }
    return runSuite(jobs, options, std::cout, std::cerr);
  } catch (const std::exception& e) {
    std::cerr << "psc_demo: error: " << e.what() << "\n";
    return 2;
  }
}
