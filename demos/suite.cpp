#include "suite.h"

#include "plots.h"
#include "psc/error.h"
#include "report.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ostream>

namespace psc::demo {
namespace {

using Clock = std::chrono::steady_clock;

std::string duration(double seconds) {
  char buf[32];
  if (seconds < 60) {
    std::snprintf(buf, sizeof buf, "%.0f s", std::max(1.0, seconds));
  } else {
    std::snprintf(buf, sizeof buf, "%d min %02d s", int(seconds) / 60, int(seconds) % 60);
  }
  return buf;
}

std::string fmt(const char* format, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, format, v);
  return buf;
}

/// Cost units of a job: vertices × steps × pipelines. The seconds per unit are learnt from the
/// jobs already run; the first guess is what a 2-core laptop-class machine measured.
double units(const Scene& s, std::size_t steps, std::size_t pipelines) {
  std::size_t v = 0;
  for (const SoftBodySpec& b : s.bodies) v += b.mesh.vertices.size();
  return double(v) * double(steps) * double(pipelines);
}

std::string summary(const RunResult& r) {
  std::string s = runName(r) + ": " + fmt("%.3g", r.collision_ms_mean) + " ms coll, " +
                  fmt("%.3g", r.step_ms_mean) + " ms step (means)";
  if (r.has_strict) s += ", strict " + fmt("%.4f", r.recall_strict);
  if (r.has_strict && r.truth_strict_untestable)
    s += " (" + fmt("%.4f", r.recall_strict_testable) + " without " + std::to_string(r.truth_strict_untestable) +
         " on triangles CollideVF_SS refuses)";
  if (r.has_full) s += ", full " + fmt("%.4f", r.recall_full);
  if (r.penetration_steps) s += ", penetration " + fmt("%.3f", r.max_penetration);
  s += ", crossings max " + std::to_string(r.intersections_max) + " (" + std::to_string(r.intersections_steps) +
       " steps), tunnelled " + std::to_string(r.tunnelled_total) + " (worst step " +
       std::to_string(r.tunnelled_worst_step) + ")";
  s += ", self-crossings max " + std::to_string(r.self_intersections_max) + " (" +
       std::to_string(r.self_intersections_steps) + " steps)";
  if (r.has_self_truth) {
    s += ", self strict " + fmt("%.4f", r.self_recall_strict) + " of " + std::to_string(r.self_truth_strict_total);
    if (r.self_truth_strict_all_total > r.self_truth_strict_total)
      s += " (" + fmt("%.4f", r.self_recall_strict_all) + " of all " + std::to_string(r.self_truth_strict_all_total) +
           ", triangles CollideVF_SS refuses included)";
    s += ", " + std::to_string(r.self_contacts_found_total) + " self contacts";
    if (r.has_full) s += " (" + std::to_string(r.self_contacts_outside_truth) + " outside)";
  }
  if (r.bullet_clusters > 0)
    s += ", cluster contacts " + std::to_string(r.cluster_contacts_total) + " between bodies, " +
         std::to_string(r.self_cluster_contacts_total) + " self";
  if (r.runaway_steps)
    s += ", RUNAWAY in " + std::to_string(r.runaway_steps) + " steps (first: " + r.runaway_warning + ")";
  if (r.diverged_at_step >= 0) s += ", DIVERGED after step " + std::to_string(r.diverged_at_step);
  return s;
}

/// Collision-time ratios (means) between the runs of one job, written into every run of it;
/// Bullet's cluster runs are not among them.
void setRatios(std::vector<RunResult>& job_runs) {
  const auto collisionMean = [&](Pipeline p) {
    for (const RunResult& r : job_runs)
      if (r.pipeline == p && r.bullet_clusters == 0) return r.collision_ms_mean;
    return 0.0;
  };
  const double sensors = collisionMean(Pipeline::Sensors), bounds = collisionMean(Pipeline::Bounds),
               bullet = collisionMean(Pipeline::Bullet);
  for (RunResult& r : job_runs) {
    if (sensors > 0 && bullet > 0) r.ratio_bullet_over_sensors = bullet / sensors;
    if (bounds > 0 && bullet > 0) r.ratio_bullet_over_bounds = bullet / bounds;
    if (sensors > 0 && bounds > 0) r.ratio_bounds_over_sensors = bounds / sensors;
  }
}

}  // namespace

std::vector<Job> defaultSuite() {
  std::vector<Job> jobs;
  for (const SceneInfo& info : sceneCatalog()) {
    Job j;
    j.scene = info.name;
    j.params.resolution = 0;  // the scene's: 1000 vertices per body, cloth_fold 2000
    j.self_collision = info.name == "cloth_fold" || info.name == "tube_coil";
    jobs.push_back(j);
  }
  for (std::size_t res : {500, 1000, 2000, 4000}) {
    Job j;
    j.scene = "tori_pile";
    j.params.resolution = res;
    j.params.bodies = 8;
    j.steps = 100;
    j.warmup = 40;
    j.series = "sweep_resolution";
    jobs.push_back(j);
  }
  return jobs;
}

SuiteOptions defaultSuiteOptions() {
  SuiteOptions o;
  o.pipelines = {Pipeline::Sensors, Pipeline::Bounds, Pipeline::Bullet};
  o.json = "results/demo.json";
  o.csv = "results/demo.csv";
  o.plot_dir = "results/plots";
  return o;
}

int runSuite(const std::vector<Job>& jobs, const SuiteOptions& options, std::ostream& out, std::ostream& progress) {
  const MachineInfo machine = machineInfo();
  // Every pipeline, then two Bullet cluster runs per --bullet-clusters value.
  struct Variant {
    Pipeline pipeline;
    int clusters;
    bool direct;
  };
  std::vector<Variant> variants;
  for (Pipeline p : options.pipelines) variants.push_back({p, 0, false});
  for (int k : options.bullet_clusters)
    for (bool direct : {false, true}) variants.push_back({Pipeline::Bullet, k, direct});
  progress << "psc_demo: " << jobs.size() << " scene run(s) × " << options.pipelines.size() << " pipeline(s)";
  if (!options.bullet_clusters.empty())
    progress << " + " << 2 * options.bullet_clusters.size() << " Bullet cluster run(s)";
  progress << ", truth " << toString(options.run.truth) << "; " << machineLine(machine) << "\n";
  std::vector<RunResult> results;
  int status = 0;
  double seconds_per_unit = 1.5e-6, done_units = 0, done_seconds = 0;
  const auto suite_start = Clock::now();
  for (std::size_t i = 0; i < jobs.size(); ++i) {
    const Job& job = jobs[i];
    const auto job_start = Clock::now();
    try {
      const Scene scene = makeScene(job.scene, job.params);
      const std::size_t steps = job.steps ? job.steps : scene.default_steps;
      const double u = units(scene, steps, variants.size());
      double remaining = 0;
      for (std::size_t k = i; k < jobs.size(); ++k) {
        // Later jobs are estimated from their parameters alone (building their meshes would cost).
        const std::size_t res = jobs[k].params.resolution ? jobs[k].params.resolution
                                                          : findScene(jobs[k].scene)->default_resolution;
        const std::size_t bodies = jobs[k].params.bodies ? jobs[k].params.bodies : (findScene(jobs[k].scene)->default_bodies);
        const std::size_t st = jobs[k].steps ? jobs[k].steps : findScene(jobs[k].scene)->default_steps;
        remaining += double(res * bodies * st * variants.size());
      }
      progress << "[" << i + 1 << "/" << jobs.size() << "] " << scene.name << " (scene " << findScene(scene.name)->number
               << "): " << scene.bodies.size() << " bodies x " << scene.resolution() << " vertices, " << steps
               << " steps ... est. " << duration(u * seconds_per_unit) << " (suite left ~"
               << duration(remaining * seconds_per_unit) << ")\n";
      if (!scene.note.empty()) progress << "      " << scene.note << "\n";
      progress.flush();
      std::vector<RunResult> job_runs;
      for (const Variant& v : variants) {
        const Pipeline p = v.pipeline;
        RunOptions ro = options.run;
        ro.bullet_clusters = v.clusters;
        ro.cluster_self_direct = v.direct;
        ro.steps = steps;
        ro.self_collision = ro.self_collision || job.self_collision;
        if (job.warmup) ro.warmup = job.warmup;
        if (!ro.frames_dir.empty())
          ro.frames_name = scene.name + "_" + std::to_string(scene.resolution()) + "v_" +
                           std::to_string(scene.bodies.size()) + "b_" + runName(p, v.clusters, v.direct);
        RunResult r = runPipeline(scene, p, ro);
        r.series = job.series;
        progress << "      " << summary(r) << "\n";
        progress.flush();
        job_runs.push_back(std::move(r));
      }
      setRatios(job_runs);
      for (RunResult& r : job_runs) results.push_back(std::move(r));
      const double took = std::chrono::duration<double>(Clock::now() - job_start).count();
      done_units += u;
      done_seconds += took;
      seconds_per_unit = done_seconds / done_units;
      progress << "      done in " << duration(took) << "\n";
    } catch (const std::exception& e) {
      progress << "      FAILED: " << e.what() << "\n";
      status = 1;
    }
  }
  const double total = std::chrono::duration<double>(Clock::now() - suite_start).count();

  out << "\n" << machineLine(machine) << "\n";
  out << "recall: found ∩ truth / truth over all steps, then the worst step; pairs: body pairs in contact that got a "
         "contact;\ncoll ms, step ms: soft-soft collision time and whole step per step (means after warm-up); B/ours: "
         "Bullet's coll ms over this run's; bounds: the sensors pipeline with its sensor stage off (boxes only);\nmax "
         "pen: deepest vertex inside another closed body beyond the margins; cross, self-x: most edge-triangle crossings "
         "in a step between bodies, within one body;\nself rec: strict self recall (--self-collision)\n";
  if (options.run.flagging == FlaggingMode::Thesis &&
      std::find(options.pipelines.begin(), options.pipelines.end(), Pipeline::Sensors) != options.pipelines.end())
    out << "sensors runs: --flagging thesis (Flagging::Sensors, the thesis's flag-only mode)\n";
  out << "\n";
  printTable(out, results);
  out << "\nsuite time " << duration(total) << "\n";
  try {
    if (!options.json.empty()) {
      writeJson(options.json, machine, results);
      out << "wrote " << options.json << "\n";
    }
    if (!options.csv.empty()) {
      writeCsv(options.csv, results);
      out << "wrote " << options.csv << "\n";
    }
    if (!options.plot_dir.empty()) {
      if (!gnuplotAvailable())
        progress << "warning: gnuplot not found, no PNG plots (data and scripts written to " << options.plot_dir << ")\n";
      // The plots show the pipelines: Bullet's cluster runs are left out.
      std::vector<RunResult> without_clusters;
      if (!options.bullet_clusters.empty())
        for (const RunResult& r : results)
          if (r.bullet_clusters == 0) without_clusters.push_back(r);
      for (const std::string& png : writePlots(options.bullet_clusters.empty() ? results : without_clusters,
                                               options.plot_dir))
        out << "wrote " << png << "\n";
    }
    if (!options.run.frames_dir.empty())
      out << "frames in " << options.run.frames_dir << " (open the *_surface.pvd files in ParaView)\n";
  } catch (const std::exception& e) {
    progress << "error: " << e.what() << "\n";
    status = 1;
  }
  return status;
}

}  // namespace psc::demo
