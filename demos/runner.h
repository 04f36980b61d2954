// One run: a scene simulated for S steps by one pipeline, measured against the ground truth.
//
// Pipelines: `sensors` (psc::bullet, the default Flagging::SensorsAndBounds, or with
// --flagging thesis the thesis's flag-only Flagging::Sensors), `bounds` (the same plugin pipeline
// with Flagging::Bounds: the sensor stage switched off, boxes only; the ablation) and `bullet`
// (Bullet's own VF_SS path). Bullet's cluster runs (RunOptions::bullet_clusters = k, --bullet-clusters)
// are `bullet` runs with another soft-soft path: generateClusters(k) on every body and
// SDF_RS | CL_SS | CL_SELF instead of SDF_RS | VF_SS (run `bullet_cl<k>`), or SDF_RS | CL_SS with
// the cluster self-collision called directly (run `bullet_cl<k>_direct`; docs/BULLET.md).
//
// Collision ms (one definition for every pipeline, StepTimes::collision()): the wall time a step
// spends finding soft-soft contacts, excluding what all pipelines pay identically.
//   bullet  = face-tree refit (split out of btSoftBody::predictMotion by TimedSoftBodySolver;
//             the tree only exists because of VF_SS)
//           + the BT_PROFILE zone "Deformable Collision" during collision detection
//             (btSoftBody::defaultCollisionHandler: node-tree vs face-tree traversal + every
//             CollideVF_SS exact test, both directions, all soft-soft pairs)
//   sensors, bounds
//           = the plugin's sensor step (body sync + SensorWorld::step(): particle movement, box
//             refit, flagging, candidate sets, repartitioning) + its exact stage (CollideVF_SS on
//             the candidates)
//           + the face-tree refit and the zone if any body or pair was still left to Bullet
//             (normally 0: no VF_SS)
//   bullet cluster runs
//           = the zone during collision detection (CL_SS between bodies: cluster trees + GJK)
//           + the world's self-collision pass after the soft solve (cluster self-collision)
//             (updateClusters in predictMotion, which refits the cluster tree, is left in step ms)
// Excluded from all: the node-tree refit in predictMotion (Bullet always does it; soft-rigid
// uses that tree), broadphase, soft-rigid collision, the solvers.
// Step ms: wall time of stepSimulation minus the time the measurement hooks took inside it.
// After every step (always, whatever the truth mode) the runner counts edge–triangle crossings
// between bodies and tunnelled vertices (crossings.h), on node positions copied before
// stepSimulation and read after it; that time goes to StepTimes::hooks, not to the pipeline.
// Times are summarised over the timed steps (after the warm-up): means, medians, and the median
// over the timed steps in which the pipeline found at least one soft-soft contact.
#pragma once

#include "psc/bullet/settings.h"
#include "scenes.h"
#include "step_record.h"

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace psc::demo {

enum class Pipeline { Sensors, Bounds, Bullet };
enum class TruthMode { None, Strict, Full, Both };
/// The sensors pipeline's flagging: Default = Flagging::SensorsAndBounds, Thesis =
/// Flagging::Sensors (flag-only, thesis §3.5). The bounds pipeline is always Flagging::Bounds.
enum class FlaggingMode { Default, Thesis };

const char* toString(Pipeline p);
struct RunResult;
/// The run's name in the table, the JSON's "pipeline" and the CSV: toString(pipeline), or for
/// Bullet's cluster runs bullet_cl<k> and bullet_cl<k>_direct.
std::string runName(Pipeline p, int bullet_clusters = 0, bool cluster_self_direct = false);
std::string runName(const RunResult& r);
const char* toString(TruthMode t);
const char* toString(FlaggingMode f);

struct RunOptions {
  std::size_t steps = 0;         ///< 0 = the scene's default
  TruthMode truth = TruthMode::Both;
  bool penetration = true;       ///< inside tests after every step (closed bodies)
  std::string frames_dir;        ///< write a VTK series here; empty = none
  std::string frames_name;       ///< file stem of the series; empty = <scene>_<pipeline>
  std::size_t frame_every = 1;   ///< write every n-th step
  std::size_t warmup = 0;        ///< steps left out of the timing; 0 = min(10, max(1, steps/10))
  FlaggingMode flagging = FlaggingMode::Default;  ///< for the sensors pipeline
  std::string exact = "bullet";  ///< the sensors' exact test: bullet, robust or continuous (psc::bullet::ExactTest)
  /// Our pipelines' psc::MotionBound: "radius" (the plugin's default) or "ahead"; with exact =
  /// "continuous" the plugin uses the swept bound whatever this says.
  std::string motion_bound = "radius";
  /// Self-collision on every body of our pipelines (psc::bullet::Settings::self_collision), and the
  /// self truth for every pipeline. Bullet's own pipeline has none and stays as it is.
  bool self_collision = false;
  /// With self_collision: psc::SensorSettings::self_rest_bound for our pipelines (--no-self-rest-bound:
  /// false, the ablation of the rest-shape bound: the self chunk pairs go by their boxes alone).
  bool self_rest_bound = true;
  /// Our pipelines refit each body right after its predictMotion, nodes warm (SensorPipeline);
  /// false (--refit-in-step): in the sensor step, as a plugin without the solver hook does.
  bool refit_after_predict = true;
  /// psc::bullet::Settings::runaway_fallback for our pipelines (--runaway-fallback).
  bool runaway_fallback = false;
  /// psc::bullet::Settings::runaway_sharing for our pipelines (--no-runaway-sharing: false).
  bool runaway_sharing = true;
  /// psc::bullet::Settings::crowded_band for our pipelines (--crowded-band; 0: off).
  std::size_t crowded_band = psc::bullet::Settings{}.crowded_band;
  /// psc::bullet::Settings::contacts for our pipelines: "all" or "nearest" (--contacts).
  std::string contacts = "all";
  /// > 0: a Bullet cluster run (only with Pipeline::Bullet): generateClusters(bullet_clusters) on
  /// every body; CL_SS | CL_SELF as Bullet documents it, or with cluster_self_direct CL_SS and the
  /// cluster self-collision called directly (TimedSoftBodySolver::setCallClusterSelf).
  int bullet_clusters = 0;
  bool cluster_self_direct = false;
};

/// Everything a run measured, summarised from its per-step records. Fields that do not apply are
/// flagged by the has_* members.
struct RunResult {
  std::string scene, scene_number, title, note;
  std::string series = "scenes";  ///< which group of runs: "scenes", "sweep_resolution", "sweep_bodies"
  std::size_t resolution = 0, bodies = 0, steps = 0, vertices = 0;
  Pipeline pipeline = Pipeline::Bullet;
  std::string flagging;           ///< ours: "default", "thesis" or "bounds"; empty for Bullet's
  std::string exact = "bullet";   ///< exact test of the run (Bullet's own pipeline: always bullet)
  std::string motion_bound;       ///< ours: "ahead", "radius" or "swept"; empty for Bullet's
  bool runaway_fallback = false;  ///< ours: RunOptions::runaway_fallback
  bool runaway_sharing = false;   ///< ours: RunOptions::runaway_sharing
  std::size_t crowded_band = 0;   ///< ours: RunOptions::crowded_band
  std::string contacts;           ///< ours: RunOptions::contacts; empty for Bullet's
  bool self_rest_bound = false;   ///< ours with self-collision: RunOptions::self_rest_bound
  bool self_collision = false;    ///< the pipeline itself: ours with RunOptions::self_collision, Bullet's cluster runs
  int bullet_clusters = 0;        ///< RunOptions::bullet_clusters (0: not a cluster run)
  bool cluster_self_direct = false;
  /// Bullet's cluster runs: cluster contacts (joints) made between bodies and of a body with
  /// itself, summed over the steps (StepCounts::cluster_contacts, self_cluster_contacts).
  std::size_t cluster_contacts_total = 0, self_cluster_contacts_total = 0;
  /// The recalls below are 1 where their truth is empty (nothing was lost); the table prints "none".
  bool has_strict = false, has_full = false;
  double recall_strict = 1.0, recall_full = 1.0;
  double recall_strict_worst_step = 1.0, recall_full_worst_step = 1.0;
  double pair_recall = 1.0;
  std::size_t truth_strict_total = 0, truth_full_total = 0, found_in_strict = 0, found_in_full = 0;
  std::size_t truth_ambiguous = 0;         ///< pairs in the rounding band, not counted either way
  /// Strict-truth contacts on triangles that Bullet's CollideVF_SS refuses outright (|cross|² ≤
  /// SIMD_EPSILON): no pipeline ending in Bullet's exact test can find them.
  std::size_t truth_strict_untestable = 0;
  std::size_t found_in_strict_untestable = 0;  ///< found contacts among those (Robust, Continuous)
  double recall_strict_testable = 1.0;     ///< recall over the strict truth without those, found and true
  double scale = 1.0;                      ///< SceneParams::scale of the run
  std::size_t contacts_found_total = 0;
  std::size_t reduced_contacts_total = 0;  ///< ours: StepCounts::reduced_contacts summed
  std::size_t contacts_outside_truth = 0;  ///< only with the full truth
  std::size_t truth_pairs_total = 0, truth_pairs_found = 0;
  double exact_tests_per_step = 0.0;
  bool has_sensor_figures = false;         ///< our pipelines (sensors, bounds)
  double flagged_pairs_per_step = 0.0;
  double rounds_per_step = 0.0;
  /// Ours: each of coreCounters() (step_record.h) summed over every step run, over the steps run
  /// (as exact_tests_per_step), in that list's order.
  std::vector<double> core_counts_per_step;
  std::size_t particles = 0;
  std::size_t round_cap_hits = 0;
  std::size_t repartitions = 0;
  std::size_t fallback_pairs = 0;
  /// Ours: steps in which some body pair's contacts beyond the margins shared their weight
  /// (psc::bullet::Stats::sharing_pairs > 0), and the contacts so changed, summed over the steps.
  std::size_t sharing_steps = 0, shared_contacts = 0;
  /// Ours: of shared_contacts, those of crowded nodes in pairs that had not run away
  /// (psc::bullet::Stats::crowded_contacts, Settings::crowded_band).
  std::size_t crowded_contacts = 0;
  std::string pipeline_error;              ///< first error the plugin reported, if any
  // Timing, over the timed steps (per_step[warmup...]).
  std::size_t warmup = 0;                  ///< steps left out of the timing
  std::size_t timed_steps = 0;
  std::size_t contact_steps_timed = 0;     ///< timed steps with at least one soft-soft contact found
  double collision_ms_mean = 0.0, step_ms_mean = 0.0;
  double collision_ms_median = 0.0, step_ms_median = 0.0;
  double collision_ms_contact_median = 0.0;  ///< over the contact_steps_timed; 0 when there are none
  double collision_ms_max = 0.0, step_ms_max = 0.0;
  StepTimes stage_ms_mean, stage_ms_median;  ///< every part of StepTimes, mean and median
  double max_penetration = 0.0;
  std::size_t penetration_steps = 0;
  /// Edge–triangle crossings between bodies after a step (StepCounts::edge_crossings): the most in
  /// one step, and the steps with any.
  std::size_t intersections_max = 0, intersections_steps = 0;
  /// The same within one body, between an edge and a triangle that share no vertex
  /// (StepCounts::self_edge_crossings): a surface passing through itself.
  std::size_t self_intersections_max = 0, self_intersections_steps = 0;
  /// Self truth (RunOptions::self_collision with a strict truth): found self contacts inside the
  /// strict self truth over it, over the run, on triangles CollideVF_SS accepts; found self
  /// contacts outside the full self truth (with a full truth).
  bool has_self_truth = false;
  double self_recall_strict = 1.0;
  std::size_t self_truth_strict_total = 0, self_found_in_strict = 0, self_contacts_outside_truth = 0;
  /// The same over all pairs of the strict self truth, the triangles CollideVF_SS refuses included
  /// (1.0 asks for ExactTest::Robust or Continuous where such triangles touch).
  double self_recall_strict_all = 1.0;
  std::size_t self_truth_strict_all_total = 0, self_found_in_strict_all = 0;
  std::size_t self_contacts_found_total = 0;
  /// Steps with a body pair over the plugin's runaway rule (psc::bullet::runawayContacts: bodies
  /// inside each other or too fast for the contact radius), and the first such warning.
  std::size_t runaway_steps = 0;
  std::string runaway_warning;
  /// Vertices that passed through another body's triangle during a step without a soft-soft contact
  /// (StepCounts::tunnelled_vertices): summed over the steps, and the most in one step.
  std::size_t tunnelled_total = 0, tunnelled_worst_step = 0;
  /// The same over all vertices, with a contact or not (StepCounts::passed_vertices).
  std::size_t passed_total = 0, passed_worst_step = 0;
  /// First step after which a node position was non-finite or absurdly far out (1000 scene
  /// extents): the simulation blew up and the run stopped there; -1 = it did not.
  long diverged_at_step = -1;
  double peak_rss_mb = 0.0;
  /// Peak RSS over the first kEarlySteps steps (the whole run when it is shorter), MB: what a long
  /// run's peak is compared with (a run whose memory keeps growing with its contacts shows here).
  double peak_rss_mb_early = 0.0;
  static constexpr std::size_t kEarlySteps = 50;
  double midphase_bytes_per_vertex = 0.0;
  /// Collision ms means of the runs of the same job, filled by the suite when both ran (0 = not).
  double ratio_bullet_over_sensors = 0.0, ratio_bullet_over_bounds = 0.0, ratio_bounds_over_sensors = 0.0;
  double wall_seconds = 0.0;               ///< whole run incl. truth and output
  double truth_seconds = 0.0;
  std::vector<StepRecord> per_step;        ///< every step run, warm-up included
};

/// Builds the world for `pipeline` from `scene`, steps it and measures. Throws psc::Error when the
/// pipeline is unavailable (no plugin built).
RunResult runPipeline(const Scene& scene, Pipeline pipeline, const RunOptions& options);

/// Before each run (runPipeline calls it first): the memory earlier runs of the process freed goes
/// back to the system (glibc's malloc_trim), so that a run's peak RSS does not hold what a
/// predecessor left in the heap, and each run pays the page faults of its own memory's growth.
/// It does not make the runs of one invocation equal: the first run of a scene still measures a
/// few percent slower than the same work run after it (docs/BENCHMARK.md, "Timing"). No effect
/// outside glibc.
void releaseFreedMemory();
/// Peak resident set size of the process since the last reset, MB (VmHWM; getrusage fallback).
double peakRssMb();
/// Resets the peak to the current RSS where Linux allows it (/proc/self/clear_refs, "5").
bool resetPeakRss();

double median(std::vector<double> v);
double mean(const std::vector<double>& v);

}  // namespace psc::demo
