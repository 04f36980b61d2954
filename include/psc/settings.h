// Settings of a SensorWorld. Defaults live here, units in the comments; validate() names the
// first setting out of range. Every [beyond] item can be switched back to the thesis behaviour.
#pragma once

#include "psc/budget.h"
#include "psc/partition.h"

namespace psc {

enum class Flagging {
  /// Thesis §3.5, flag-only: particles of different bodies closer than μ flag their regions, and
  /// the candidate sets are the flagged regions (+ one ring). Not complete: kept to be measured.
  Sensors,
  /// Default. Flat per-body / per-region / per-chunk boxes refit every step give a coarse,
  /// complete cull; the sensor particles then decide which region pairs, chunks, vertices and
  /// triangles reach the exact test (see docs/METHOD.md). Never loses a contact inside the radius.
  SensorsAndBounds,
  /// Ablation of the default: the same pipeline with the sensor stage switched off (boxes only).
  Bounds,
};

/// How a vertex's motion over the step (previous → current position) widens what it can touch.
/// Only used when a body has a previous-position view.
enum class MotionBound {
  /// Default: a vertex reaches margin_A + margin_B + motion_factor·|x_v − x_v,prev| around its
  /// current position, against triangles at their current positions: Bullet's CollideVF_SS
  /// acceptance radius (motion_factor = 2).
  Radius,
  /// Every (vertex, triangle) pair that comes within margin_A + margin_B of each other at some time
  /// of the step, both moving linearly: the vertex's path against the triangle's swept volume (the
  /// box of its six positions). For continuous tests; motion_factor is not used. A fast vertex
  /// reaches half its step around its path's midpoint instead of twice its step around its end.
  /// Flagging::Sensors (the thesis's mode) does not support it.
  Swept,
  /// The pairs inside Radius's radius that the motion heads into: the vertex's path ahead over
  /// `ahead_steps` more steps at its step's displacement (x_v → x_v + ahead_steps·(x_v − x_v,prev))
  /// comes within margin_A + margin_B of the triangle's path ahead (each corner likewise), or the
  /// vertex already lies within the margins. A subset of Radius's pairs: every pair within the margins,
  /// every pair the vertex and the triangle would meet in if they kept going, and none of the pairs
  /// a fast vertex only passes beside or leaves behind, which Bullet's contact response pushes out to
  /// the whole radius (docs/METHOD.md §5.4). Two-body pairs only; self pairs and Flagging::Sensors
  /// (the thesis's mode) use Radius.
  Ahead,
};


enum class AreaEstimator {
  FourDirectionWalk,  ///< thesis §3.6: walk ±X, ±Y in the particle's tangent plane, area = rectangle
  TrueArea,           ///< [beyond] the region's share of triangle areas (default)
};

struct RepartitionSettings {
  bool enabled = true;
  AreaEstimator estimator = AreaEstimator::TrueArea;
  int check_every = 10;                ///< steps between checks of a body (≥ 1)
  double area_trigger = 1.5;           ///< repartition when a region's area > area_trigger × A* (≥ 1; thesis: 1)
  /// [beyond] A check's TrueArea reads every k-th of a region's chunks, k = its chunk count /
  /// area_sample_chunks (at least 1): the region's area is their area now times the region's over
  /// theirs at partitioning (exact for an even stretch). Exact for a region of fewer than
  /// 2 × area_sample_chunks chunks; 0 = every chunk, always exact. A* is always exact.
  std::size_t area_sample_chunks = 16;
  double edge_stretch_trigger = 1.5;   ///< [beyond] ... or the longest edge > trigger × its length at
                                       ///< partitioning (≥ 1; 0 = off); also refreshes μ. Only in
                                       ///< Flagging::Sensors, the one mode where μ decides
};

struct SensorSettings {
  /// μ_geom = mu_edge_factor × the larger mean edge length of the two bodies (length units).
  /// Thesis §5.1.4 proves μ must be at least half the mean edge: factor ≥ 0.5.
  double mu_edge_factor = 1.0;
  /// Effective radius of the pull, length units. 0 = auto, recomputed every step: twice the
  /// largest region box diagonal (two touching regions have their particles closer than the sum
  /// of their diameters, so they always feel each other, and each particle only looks at its
  /// neighbourhood; the thesis uses the largest distance between initial particles).
  /// Always clamped above the largest μ of a resting body (mu_edge_factor × its mean edge + twice
  /// its margin); the thesis mode's μ grows with motion beyond that (motion_factor · |Δx|), and its
  /// flagging grid takes the larger of the two, but the pull reaches only R_eff.
  double r_eff = 0.0;
  /// Movement rounds per step before giving up (≥ 1) when the particles move until stable; a hit
  /// is counted in StepStats::round_cap_hits.
  int max_rounds = 64;
  /// [beyond] Movement rounds per step in Flagging::SensorsAndBounds and Flagging::Bounds (≥ 0;
  /// 0 = until stable, up to max_rounds, as in the thesis). The particles keep their vertices
  /// between steps and so track the closest points across steps: on 8 tori × 2,000 vertices one
  /// round a step gives the same region pairs, separations and candidates as moving until stable
  /// (13.5 rounds a step) at a seventh of the cost. Flagging::Sensors, whose flags are the
  /// particles' proximity itself, always moves them until stable.
  int rounds_per_step = 1;
  /// [beyond] Within one step a particle never hops back to the vertex it just left. Pure Jacobi
  /// updates (thesis §3.4) let two particles approaching head-on swap places forever; off = thesis.
  bool no_backtrack = true;
  Flagging flagging = Flagging::SensorsAndBounds;
  /// Candidate sets extend by one vertex ring around the flagged regions (thesis §3.5).
  bool one_ring = true;
  /// A vertex v of A counts as touching a triangle of B within
  ///   margin_A + margin_B + motion_factor·|x_v − x_v,prev|     (length units)
  /// Bullet's CollideVF_SS uses 2. Only used when a body has a previous-position view. ≥ 0.
  double motion_factor = 2.0;
  MotionBound motion_bound = MotionBound::Radius;
  /// MotionBound::Ahead: how many steps ahead (> 0, finite) the paths are followed. 1 = the pairs
  /// that would meet during the next step if nothing changed: the discrete test then sees a
  /// crossing one step before it happens. 2 reaches as far as Bullet's radius (motion_factor = 2)
  /// but let fast_impact run away at 2,000 vertices (docs/DECISIONS.md).
  double ahead_steps = 1.0;
  /// [beyond] Self-collision: a body's self contact radius is the larger of 2 × margin (what two
  /// bodies with its margin would use) and this × the mean edge length of its rest shape
  /// (psc::selfContactRadius). A vertex-face test stops two sheets of one body from passing
  /// through each other only when its radius spans about an edge: otherwise their edges cross
  /// between the vertices. tube_coil (margin 0.05) at 996 vertices (mean edge 0.143) had 30
  /// crossing edge-triangle pairs at 2 × margin, none at 1 × or 1.25 × the mean edge; at 2,000
  /// vertices (mean edge ~0.1) 11 at 1 ×, none at 1.25 ×. ≥ 0; 0 = 2 × margin. The exclusion at
  /// rest (below) grows with it: parts closer at rest than self_rest_exclusion × this radius
  /// never collide, so a mesh too coarse for its folds (tube_coil at 300 vertices) passes through.
  double self_radius_edges = 1.25;
  /// [beyond] Self-collision: rule out a body's chunk pairs whose surface has not bent since its
  /// rest shape enough to touch itself (a rigid motion fitted to each region carries the rest shape
  /// to within a measured deviation of where it is now; docs/METHOD.md §6.3). Off = box tests only.
  /// MotionBound::Radius only.
  bool self_rest_bound = true;
  /// Self-collision: a vertex and a triangle of one body closer than this × the self contact
  /// radius in the body's rest shape are never self candidates (SensorWorld::setSelfCollision). ≥ 1.
  double self_rest_exclusion = 2.0;
  /// [beyond] A body gets at most (vertices in triangles / min_region_vertices) particles from the
  /// budget (at least 1; an explicit BodyDesc::particles is not capped). The thesis's budget counts
  /// parts, not vertices: 8 HACD parts × 12 give a 500-vertex torus ~100 regions of 5 vertices.
  /// 1 = the thesis's budget unchanged.
  std::size_t min_region_vertices = 64;
  /// [beyond] Vertices per chunk of the bounds layer: smaller = tighter boxes, more boxes. 0 (the
  /// default) = by the body's size, chunkVerticesFor(); otherwise at least 4.
  std::size_t chunk_vertices = 0;
  /// Build (vertex, triangle) candidate pairs in step(); off = flagged pairs only.
  bool build_candidates = true;
  /// [beyond] Of each vertex's candidates against one body (its own under self-collision), keep
  /// only those whose distance (the candidate filter's exact point-triangle distance) is within a
  /// relative 1e-4 of the vertex's least: its nearest triangle and near ties. For an exact test that
  /// accepts every pair within the contact radius and a solver that keeps one contact per vertex
  /// (psc::bullet's Robust test with ContactSet::NearestFace sets it): the exact stage then sees
  /// about one pair per vertex instead of every triangle within the radius, and once a vertex's
  /// nearest so far is known its probes skip the triangles beyond that band (from the first probe
  /// on for a vertex that had candidates last step: its distance now to the triangle it kept then
  /// starts the band, StepStats::nearest_seeded). StepStats counts the
  /// pairs measured and left out (candidates_not_nearest). MotionBound::Swept has no such distance, and the thesis's
  /// flag-only mode (Flagging::Sensors) no such filter: both ignore it.
  bool nearest_candidates = false;
  /// [beyond] With MotionBound::Radius: also every two-body pair that comes within margin_A +
  /// margin_B at some time of the step, vertex and triangle both moving linearly, as
  /// MotionBound::Swept keeps them: the union of the two bounds, for a continuous test that also
  /// wants Bullet's radius (psc::bullet's ExactTest::Continuous sets it). The boxes then hold both
  /// positions of every vertex besides the motion term, and a pair is kept when its distance now
  /// is below the vertex's radius or below margin_A + margin_B + |Δx_v| + the largest motion of the
  /// triangle's corners (a pair that met during the step is no farther apart now). It reaches a
  /// slow vertex that a fast triangle sweeps over, which Radius alone, whose reach grows with the
  /// vertex's own motion, leaves out. A vertex's probes reach at least its own path (margins +
  /// |Δx_v|) whatever motion_factor is. A body's pairs with itself keep the self rule's radius.
  /// nearest_candidates is off with it (a crossing test needs every pair, not each vertex's
  /// nearest). Ignored with Swept, Ahead, a pair on SensorWorld::setPairAhead, and the thesis's
  /// flag-only mode.
  bool meeting_pairs = false;

  PartitionSettings partition;
  DecompositionSettings decomposition;
  RepartitionSettings repartition;
};

/// The chunk size a body of `vertices` vertices (in triangles) gets: SensorSettings::chunk_vertices,
/// or where that is 0, 32 below 4,096 vertices and 64 from there. A body whose nodes no longer stay
/// in the cache pays for every vertex a chunk boundary makes it add to a second box and for every
/// chunk pair it gathers; bigger chunks there cut both (docs/DECISIONS.md, "Stop 41").
inline std::size_t chunkVerticesFor(const SensorSettings& s, std::size_t vertices) {
  if (s.chunk_vertices != 0) return s.chunk_vertices;
  return vertices < 4096 ? 32 : 64;
}

/// Throws psc::Error(InvalidSettings) naming the first setting out of range.
void validate(const SensorSettings& settings);

}  // namespace psc
