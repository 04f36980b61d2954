// A list of runs (scenes × parameters × pipelines) with progress, the table, and the outputs.
#pragma once

#include "runner.h"
#include "scenes.h"

#include <iosfwd>
#include <string>
#include <vector>

namespace psc::demo {

/// One scene with one set of parameters; every pipeline of the suite runs it from the same
/// initial state, one after the other in this process.
struct Job {
  std::string scene;
  SceneParams params;
  std::size_t steps = 0;            ///< 0 = the scene's default
  std::string series = "scenes";    ///< "scenes", "sweep_resolution" or "sweep_bodies"
  std::size_t warmup = 0;           ///< steps left out of the timing; 0 = RunOptions' rule
  bool self_collision = false;      ///< RunOptions::self_collision for this job (or the suite's)
};

struct SuiteOptions {
  std::vector<Pipeline> pipelines = {Pipeline::Sensors, Pipeline::Bullet};
  RunOptions run;                    ///< truth, penetration, frames (steps come from the job)
  /// --bullet-clusters: after the pipelines, for each k two Bullet cluster runs of every job,
  /// bullet_cl<k> (CL_SS | CL_SELF as documented) and bullet_cl<k>_direct (runner.h). Left out of
  /// the collision-time ratios and the plots.
  std::vector<int> bullet_clusters;
  std::string json, csv, plot_dir;   ///< empty = not written
};

/// The default suite (psc_demo without arguments): every scene at 1000 vertices per body with its
/// default steps (the self-collision scenes, cloth_fold and tube_coil, with self-collision on), then a resolution sweep of the tori pile (8 bodies, 500-4000 vertices per body,
/// 100 steps timed from step 40 on, when the pile is in contact) for the time-vs-size plot; all
/// three pipelines (sensors, bounds, bullet) run every job.
std::vector<Job> defaultSuite();
SuiteOptions defaultSuiteOptions();

/// Runs every job, prints a progress line per job with an estimate to `progress` and the table to
/// `out`, writes JSON/CSV/plots. Returns 0, or 1 when a run failed (the others still run).
int runSuite(const std::vector<Job>& jobs, const SuiteOptions& options, std::ostream& out, std::ostream& progress);

}  // namespace psc::demo
