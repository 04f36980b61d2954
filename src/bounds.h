// Private: the default midphase (Flagging::SensorsAndBounds) and its boxes-only ablation
// (Flagging::Bounds). See docs/METHOD.md, "Coarse cull and sensor decision".
//
// 1. Refit: flat boxes per chunk (≤ chunk_vertices vertices and the triangles they own), region
//    and body, from the positions, every step: O(M), no tree.
// 2. Coarse cull: body pairs and region pairs whose grown boxes overlap, found by sort-and-sweep.
// 3. Sensor decision (SensorsAndBounds only): the segment between the particles of the two
//    regions is a candidate separating axis n. The support extents of the two regions' chunks
//    along n prove the pair apart, drop chunks outside the slab, and drop vertices and triangles
//    that cannot reach the other side's extent along n.
// 4. Chunk pairs by sort-and-sweep; candidate (vertex, triangle) pairs inside each chunk pair.
// Every step is conservative: each (vertex, triangle) pair of two bodies closer than
// margin_A + margin_B + motion_factor·|x_v − x_v,prev| comes out as a candidate, exactly once.
#pragma once

#include "body.h"
#include "psc/world.h"

#include <vector>

namespace psc::detail {

/// What a refit measures besides the boxes (b.shape), for the repartition check.
struct Measure {
  enum Kind { None, Sampled, Full };
  Kind kind = None;
  /// Each region's area from about this many of its chunks (RepartitionSettings::area_sample_chunks;
  /// 0 = every chunk).
  std::size_t sample_chunks = 0;
};

/// Refits b's chunk, region and body boxes; throws psc::Error naming the first non-finite vertex.
/// With a measure, also fills b.shape: each region's area and the longest edge. Measure::Full reads
/// every triangle (and fills b.shape.chunk_area); Measure::Sampled, with b.chunk_area_ref from a
/// full measure of the same chunks, reads every k-th chunk of a region and scales their area now by
/// the region's over theirs in the reference (the exact sum where k is 1; max_edge then theirs).
/// `swept` (MotionBound::Swept): the boxes hold the previous positions too and no motion term.
/// With `rest_fit` (a self-colliding body, MotionBound::Radius), the same pass fills b.rest_fit,
/// the rest-shape bound of the self-collision cull. `paths` (MotionBound::Radius with
/// SensorSettings::meeting_pairs): the boxes hold the previous positions too, as with `swept`, and
/// the motion term is kept.
void refitBounds(Body& b, Measure measure, bool swept, bool rest_fit = false, bool paths = false);

/// SensorSettings::nearest_candidates: each vertex's nearest triangles of the last step, per
/// ordered body pair. The next step's candidate stage starts each such vertex's search from its
/// distance to them now: an upper bound on its nearest, so from its first probe the search skips
/// what the band of its nearest would drop in the end (the same candidates, fewer tests).
struct NearestSeeds {
  struct Pair {
    BodyId vb = kInvalidBody, tb = kInvalidBody;
    /// Body::partition_number of each when recorded: a repartition renumbers tb's chunk
    /// triangles, so the pair's seeds are then ignored.
    std::uint64_t v_partition = 0, t_partition = 0;
    std::vector<std::pair<Index, Index>> seeds;  ///< (vertex of vb, owned-triangle index in tb's chunks)
  };
  std::vector<Pair> pairs;  ///< the last step's, sorted by (vb, tb)
  std::vector<Pair> next;   ///< this step's, while collecting (each takes over its last list's memory)
  Pair* find(BodyId vb, BodyId tb);
  const Pair* find(BodyId vb, BodyId tb) const { return const_cast<NearestSeeds*>(this)->find(vb, tb); }
  /// The bytes of the seeds of vb's vertices.
  std::size_t bytes(BodyId vb) const {
    std::size_t n = 0;
    for (const Pair& p : pairs)
      if (p.vb == vb) n += sizeof(Pair) + p.seeds.capacity() * sizeof(p.seeds[0]);
    return n;
  }
};

struct CullParams {
  double motion_factor = 2.0;  ///< MotionBound::Radius; 0 with `swept`
  bool swept = false;          ///< MotionBound::Swept
  /// SensorSettings::meeting_pairs with MotionBound::Radius: two-body pairs also kept when they
  /// can have met within the margins during the step (the boxes hold both positions).
  bool meeting = false;
  double ahead_steps = 0.0;    ///< MotionBound::Ahead: SensorSettings::ahead_steps (two-body probes
                               ///< against the paths ahead); 0 = not Ahead
  bool use_sensors = true;     ///< false: Flagging::Bounds (the ablation)
  /// MotionBound::Radius: body pairs (ids, first < second, sorted) on the Ahead bound with
  /// `pair_ahead_steps` (SensorWorld::setPairAhead).
  const std::vector<std::pair<BodyId, BodyId>>* ahead_pairs = nullptr;
  double pair_ahead_steps = 1.0;
  double self_rest_exclusion = 2.0;  ///< SensorSettings::self_rest_exclusion
  double self_radius_edges = 1.0;    ///< SensorSettings::self_radius_edges
  bool self_rest_bound = true;       ///< SensorSettings::self_rest_bound
  bool nearest = false;              ///< SensorSettings::nearest_candidates (not with `swept`)
  /// With `nearest`: the last step's nearest triangles (read), and this step's (written).
  NearestSeeds* seeds = nullptr;
  /// The candidate list's length at the last step: when the list must grow, its growth since then
  /// sets the room taken ahead (cullAndCollect).
  std::size_t last_candidates = 0;
};

/// The pairs (i < j) of `bodies` whose grown body boxes overlap, by sort-and-sweep, sorted.
std::vector<std::pair<Index, Index>> overlappingBodies(const std::vector<Body*>& bodies, const CullParams& params);

using BodyPairs = std::vector<std::pair<Index, Index>>;

/// For each body, whether each of its regions' grown boxes reaches the grown box of another body
/// it overlaps (`pairs` = overlappingBodies): the regions whose particles can take part in a
/// sensor decision this step.
std::vector<std::vector<char>> regionsNearOtherBodies(const std::vector<Body*>& bodies, const BodyPairs& pairs,
                                                      const CullParams& params);

/// Flags the region pairs of different bodies that reach the candidate stage and appends the
/// candidate pairs, grouped and sorted by (vertex_body, triangle_body). `bodies` ascending by id;
/// `pairs` = overlappingBodies(bodies, params).
/// Adds to the cull's counters in `stats` (body_pairs … candidate_probes) and to ms_candidates
/// (the time inside chunk pairs).
void cullAndCollect(const std::vector<Body*>& bodies, const BodyPairs& pairs, const CullParams& params,
                    std::vector<FlaggedPair>& flagged,
                    std::vector<CandidatePair>& candidates, StepStats& stats);

/// The candidate stage's box probes run four at a time with AVX2 where the processor has it
/// (checked once), else two at a time with SSE2 (x86-64's baseline); both give the same candidates.
/// Whether the AVX2 path exists on this processor:
bool avx2ProbesAvailable();
/// Allows (the default) or forbids the AVX2 path, process-wide: for the test that the two agree.
void allowAvx2Probes(bool allowed);

/// The candidate stage's exact distance (MotionBound::Radius): the squared distance from p to the
/// triangle (a, b, c), branch-free (the least of the distances to the edges and, where p projects
/// inside, to the plane); never NaN, degenerate triangles included.
double filterDistance2(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c);
/// The same for four pairs: with the AVX2 path where it is available and allowed, otherwise one at
/// a time. The two give the same bits.
void filterDistance2x4(const Vec3* const p[4], const Vec3* const a[4], const Vec3* const b[4], const Vec3* const c[4],
                       double out[4]);

}  // namespace psc::detail
