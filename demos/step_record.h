// What one simulation step of a benchmark run measured: one record per step, filled where each
// figure happens (the runner around Bullet's step and in its collision hooks; SensorPipeline from
// the plugin's Stats). Times are kept apart from counts; the run's summary (RunResult) is computed
// from the records alone.
#pragma once

#include "psc/world.h"

#include <array>
#include <cstddef>
#include <string>
#include <utility>

namespace psc::demo {

/// Wall-clock times of one step, milliseconds.
struct StepTimes {
  double step = 0.0;             ///< stepSimulation minus `hooks`
  /// The measurement done inside the step (contacts, truth) and the crossing counts around it:
  /// not the pipeline's.
  double hooks = 0.0;
  double truth = 0.0;            ///< of `hooks`: the ground truth
  /// Of `hooks`: the measurements after the step (crossing and tunnelling counts, and the
  /// penetration unless it is off), on two threads (Run::measureAfterStep), and the positions
  /// copied before the step for them.
  double crossings = 0.0;
  double detect = 0.0;           ///< whole performDiscreteCollisionDetection (a cross-check)
  /// Bullet's face-tree refit, split out of btSoftBody::predictMotion (TimedSoftBodySolver). The
  /// tree exists only for VF_SS: normally 0 for our pipelines.
  double face_refit = 0.0;
  /// The BT_PROFILE zone "Deformable Collision": Bullet's node-tree vs face-tree traversal and
  /// every CollideVF_SS test. For our pipelines only the pairs the plugin handed back to Bullet.
  double traversal_exact = 0.0;
  /// Bullet's cluster runs only (--bullet-clusters): the world's self-collision pass after the soft
  /// solve, where cluster self-collision happens (TimedSoftBodySolver::lastSelfPassMs). 0 otherwise.
  double cluster_self = 0.0;
  // Our pipelines, from psc::bullet::Stats (0 for Bullet's).
  double sensor_step = 0.0;      ///< Stats::ms_sensor_step: body sync + SensorWorld::step()
  double exact = 0.0;            ///< Stats::ms_exact: the exact stage on the candidates
  double particle = 0.0;         ///< StepStats::ms_sensors: particle movement
  double refit = 0.0;            ///< StepStats::ms_refit: body / region / chunk box refit
  double flagging = 0.0;         ///< StepStats::ms_flagging: body / region pairing, sensor decisions
  double candidates = 0.0;       ///< StepStats::ms_candidates
  double repartition = 0.0;      ///< StepStats::ms_repartition
  double core_total = 0.0;       ///< StepStats::ms_total: the whole SensorWorld::step()

  /// Soft-soft collision time of the step, one definition for every pipeline (see runner.h).
  double collision() const { return face_refit + traversal_exact + cluster_self + sensor_step + exact; }
};

/// Counts of one step.
struct StepCounts {
  std::size_t contacts_found = 0;  ///< distinct soft-soft (node, face) contacts Bullet's solver sees
  std::size_t exact_tests = 0;     ///< CollideVF_SS tests (Bullet: counted by the probe; ours: the plugin's)
  /// Ours with --contacts nearest: contacts the exact test accepted and the reduction left out
  /// (psc::bullet::Stats::reduced_contacts), not in contacts_found.
  std::size_t reduced_contacts = 0;
  // Our pipelines, from psc::bullet::Stats.
  bool sensed = false;             ///< the plugin ran its sensor step this step
  std::size_t particles = 0, flagged_pairs = 0, candidate_pairs = 0, round_cap_hits = 0, repartitions = 0;
  std::size_t fallback_pairs = 0;  ///< soft-soft pairs the plugin handed back to Bullet's algorithm
  std::size_t sharing_pairs = 0, shared_contacts = 0;  ///< psc::bullet::Stats::sharing_pairs, shared_contacts
  std::size_t crowded_contacts = 0;                    ///< psc::bullet::Stats::crowded_contacts
  long rounds = 0;
  // Against the ground truth of this step's collision pass (all 0 without truth).
  std::size_t truth_strict = 0, truth_full = 0;          ///< truth contacts inside each radius
  std::size_t found_in_strict = 0, found_in_full = 0;    ///< found contacts inside each radius
  std::size_t outside_truth = 0;                         ///< found contacts outside the full truth
  std::size_t truth_pairs = 0, truth_pairs_found = 0;    ///< body pairs in contact, of them with a contact found
  std::size_t truth_ambiguous = 0;                       ///< truth contacts in the rounding band
  std::size_t truth_strict_untestable = 0;               ///< strict truth on triangles CollideVF_SS refuses
  std::size_t found_in_strict_untestable = 0;            ///< found contacts of those (Robust, Continuous)
  // Self-collision, against the self truth (only with RunOptions::self_collision): a body's own
  // (vertex, triangle) pairs the exclusion rule leaves in (ground_truth.h, GroundTruth::computeSelf).
  std::size_t self_contacts_found = 0;                   ///< distinct soft-soft contacts of a body with itself
  /// Strict self truth and found self contacts inside it, both only on triangles CollideVF_SS
  /// accepts (|cross|² > SIMD_EPSILON).
  std::size_t self_truth_strict = 0, self_found_in_strict = 0;
  /// The same over all pairs, the triangles CollideVF_SS refuses included (what Robust can find).
  std::size_t self_truth_strict_all = 0, self_found_in_strict_all = 0;
  std::size_t self_outside_truth = 0;                    ///< found self contacts outside the full self truth
  // After the step.
  std::size_t penetrating_vertices = 0;                  ///< inside another closed body beyond the margins
  std::size_t runaway_pairs = 0;                         ///< body pairs over the runaway rule (runner.cpp)
  std::size_t edge_crossings = 0;                        ///< (edge, triangle) crossings between bodies (crossings.h)
  std::size_t self_edge_crossings = 0;                   ///< (edge, triangle) crossings within one body, no shared vertex
  /// Vertices whose path over the step passed through a moving triangle of another body, of those
  /// that had no soft-soft contact in the step (crossings.h).
  std::size_t tunnelled_vertices = 0;
  /// The same of all vertices, those with a contact included: passages the contacts did not stop.
  std::size_t passed_vertices = 0;
  /// Bullet's cluster runs: contacts (joints) its cluster collision made between bodies during
  /// collision detection, and of a body with itself in the self pass.
  std::size_t cluster_contacts = 0, self_cluster_contacts = 0;
};

/// The core's counts (psc::StepStats) that the JSON reports as `core_counts_per_step`, each by its
/// StepStats name: how many body, region and chunk pairs, gathers, probes and candidates a step
/// took, which is what explains a stage's time. One list for the pipeline that fills them and the
/// report that writes them.
using CoreCounter = std::pair<const char*, std::size_t psc::StepStats::*>;
inline const std::array<CoreCounter, 28>& coreCounters() {
  static const std::array<CoreCounter, 28> list = {{
      {"particle_moves", &psc::StepStats::particle_moves},
      {"neighbor_pairs", &psc::StepStats::neighbor_pairs},
      {"flagged_pairs", &psc::StepStats::flagged_pairs},
      {"flagged_by_sensors", &psc::StepStats::flagged_by_sensors},
      {"flagged_by_bounds_only", &psc::StepStats::flagged_by_bounds_only},
      {"body_pairs", &psc::StepStats::body_pairs},
      {"region_pairs", &psc::StepStats::region_pairs},
      {"region_pairs_separated", &psc::StepStats::region_pairs_separated},
      {"chunks_in", &psc::StepStats::chunks_in},
      {"chunks_dropped", &psc::StepStats::chunks_dropped},
      {"chunk_pairs", &psc::StepStats::chunk_pairs},
      {"vertices_dropped", &psc::StepStats::vertices_dropped},
      {"candidate_vertices", &psc::StepStats::candidate_vertices},
      {"candidate_triangles", &psc::StepStats::candidate_triangles},
      {"candidate_probes", &psc::StepStats::candidate_probes},
      {"candidates_beyond_reach", &psc::StepStats::candidates_beyond_reach},
      {"nearest_seeded", &psc::StepStats::nearest_seeded},
      {"candidates_not_nearest", &psc::StepStats::candidates_not_nearest},
      {"candidate_pairs", &psc::StepStats::candidate_pairs},
      {"self_region_pairs", &psc::StepStats::self_region_pairs},
      {"self_candidate_pairs", &psc::StepStats::self_candidate_pairs},
      {"self_excluded_pairs", &psc::StepStats::self_excluded_pairs},
      {"self_region_pairs_unbent", &psc::StepStats::self_region_pairs_unbent},
      {"self_chunk_pairs_unbent", &psc::StepStats::self_chunk_pairs_unbent},
      {"self_vertices_unbent", &psc::StepStats::self_vertices_unbent},
      {"round_cap_hits", &psc::StepStats::round_cap_hits},
      {"repartitions", &psc::StepStats::repartitions},
      {"bodies", &psc::StepStats::bodies},
  }};
  return list;
}

struct StepRecord {
  StepTimes ms;
  StepCounts n;
  /// Ours: the core's counts of the step's sensor step (its times are in `ms`); zero for Bullet's
  /// pipeline and in steps without one.
  psc::StepStats core;
  double max_penetration = 0.0;  ///< length units, deepest of the penetrating vertices
  std::string error;             ///< the plugin's error or skip reason this step, if any
  std::string runaway;           ///< the first runaway pair's warning this step, if any
};

}  // namespace psc::demo
