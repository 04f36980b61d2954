// A world of sensor bodies: add, remove, update after deformation, and one step() that moves the
// particles, flags region pairs and builds the candidate (vertex, triangle) pairs for the exact
// test. Request in, result out; all state lives in the world (no globals), so several worlds can
// be stepped in several threads.
#pragma once

#include "psc/budget.h"
#include "psc/mesh.h"
#include "psc/partition.h"
#include "psc/settings.h"
#include "psc/types.h"

#include <algorithm>

#include <map>
#include <memory>
#include <string>
#include <vector>

namespace psc {

/// What a body is made of. Positions are read in place through the views on every step, so the
/// memory behind them must stay valid until the next setPositions() / removeBody().
struct BodyDesc {
  std::vector<Triangle> triangles;
  PositionView positions;
  /// Positions at the previous step (optional): gives the motion term of the contact radius.
  PositionView previous;
  double margin = 0.0;            ///< collision margin of this body, length units (0 to kMaxCoordinate)
  std::size_t particles = 0;      ///< > 0: override the particle budget
  bool deformable = true;         ///< false: a rigid mesh, never checked for repartitioning
  /// Also hand over (vertex, triangle) pairs of this body with itself (SensorWorld::setSelfCollision).
  bool self_collision = false;
  /// Optional convex parts (e.g. shared by copies of one mesh); computed with HACD when empty.
  std::shared_ptr<const ConvexParts> parts;
  std::string name;               ///< used in error messages and reports
};

/// Where a particle is.
struct ParticleState {
  BodyId body = kInvalidBody;
  Index region = 0;
  Index vertex = 0;
};

/// Two regions of two different bodies flagged in one step; body_a < body_b.
struct FlaggedPair {
  BodyId body_a = kInvalidBody;
  Index region_a = 0;
  BodyId body_b = kInvalidBody;
  Index region_b = 0;
  bool by_sensors = false;  ///< Flagging::Sensors: particles closer than μ (thesis §3.5)
  bool by_bounds = false;   ///< default / Bounds: the grown boxes overlap and the sensor axis did not separate them
  bool operator==(const FlaggedPair& o) const {
    return body_a == o.body_a && region_a == o.region_a && body_b == o.body_b && region_b == o.region_b &&
           by_sensors == o.by_sensors && by_bounds == o.by_bounds;
  }
};

/// A (vertex of one body, triangle of another) pair to hand to the exact test, or of one body with
/// itself (vertex_body == triangle_body) when that body has self-collision on. Each appears at
/// most once per step. StepResult::candidates is sorted by (vertex_body, triangle_body); the order
/// inside one such group is deterministic but otherwise unspecified.
struct CandidatePair {
  BodyId vertex_body = kInvalidBody;
  Index vertex = 0;
  BodyId triangle_body = kInvalidBody;
  Index triangle = 0;
  bool operator==(const CandidatePair& o) const {
    return vertex_body == o.vertex_body && vertex == o.vertex && triangle_body == o.triangle_body &&
           triangle == o.triangle;
  }
};

struct StepStats {
  std::size_t bodies = 0;
  std::size_t particles = 0;
  int rounds = 0;                    ///< movement rounds this step (Jacobi sweeps)
  std::size_t round_cap_hits = 0;    ///< 1 when max_rounds stopped the movement before it was stable
  std::size_t particle_moves = 0;    ///< hops made, summed over particles and rounds
  std::size_t neighbor_pairs = 0;    ///< Flagging::Sensors: particle pairs of different bodies within R_eff after movement (0 otherwise)
  std::size_t flagged_pairs = 0;           ///< region pairs that reach the candidate stage
  std::size_t flagged_by_sensors = 0;      ///< Flagging::Sensors: flagged by particles within μ
  std::size_t flagged_by_bounds_only = 0;  ///< default / Bounds: flagged by the boxes (and not separated)
  // The default midphase (Flagging::SensorsAndBounds and its ablation Flagging::Bounds):
  std::size_t body_pairs = 0;              ///< body pairs whose grown boxes overlap
  std::size_t region_pairs = 0;            ///< region pairs whose grown boxes overlap
  std::size_t region_pairs_separated = 0;  ///< of those: proved apart along their sensor axis
  std::size_t chunks_in = 0;               ///< chunks reaching the other region's box (per region pair)
  std::size_t chunks_dropped = 0;          ///< of those: outside the sensor slab
  std::size_t chunk_pairs = 0;             ///< chunk pairs examined
  std::size_t vertices_dropped = 0;        ///< vertices dropped by the sensor slab inside chunk pairs
  std::size_t candidate_vertices = 0;      ///< vertices examined (per flagged pair or chunk pair and direction)
  std::size_t candidate_triangles = 0;     ///< triangles examined (likewise)
  std::size_t candidate_probes = 0;        ///< (vertex, triangle) box tests made to find them
  std::size_t candidates_beyond_reach = 0; ///< pairs whose boxes meet but whose exact distance exceeds the radius (MotionBound::Radius)
  std::size_t nearest_seeded = 0;           ///< SensorSettings::nearest_candidates: vertices whose search started from the distance to their last step's nearest triangles
  std::size_t candidates_not_nearest = 0;  ///< SensorSettings::nearest_candidates: pairs measured within reach and left out, farther than their vertex's nearest (not those its probes already skipped)
  std::size_t candidate_pairs = 0;         ///< unique pairs handed to the exact test
  std::size_t self_region_pairs = 0;       ///< region pairs of one body (self-collision) whose grown boxes overlap
  std::size_t self_candidate_pairs = 0;    ///< of candidate_pairs: a body with itself
  std::size_t self_excluded_pairs = 0;     ///< self pairs the boxes kept but the exclusion rule drops (incident, or close at rest), past the rest-centroid pre-test (a triangle whose rest centroid is within the exclusion distance is dropped with the box test, uncounted)
  std::size_t self_region_pairs_unbent = 0; ///< of self_region_pairs: ruled out whole by the rest-shape bound
  std::size_t self_chunk_pairs_unbent = 0;  ///< (vertex chunk, triangle chunk) pairs of one body the rest-shape bound ruled out
  std::size_t self_vertices_unbent = 0;     ///< vertices of self chunk pairs past the box test that the rest-shape bound ruled out against the triangle chunk
  std::size_t repartitions = 0;            ///< bodies re-partitioned this step
  double r_eff = 0.0;                      ///< R_eff used this step (length units)
  double ms_sensors = 0.0;                 ///< particle movement (wall clock)
  double ms_refit = 0.0;                   ///< refit of the body / region / chunk boxes (with refitNow's since the last step)
  double ms_flagging = 0.0;                ///< pairing bodies and regions, the sensors' decisions
  double ms_candidates = 0.0;              ///< candidate pairs
  double ms_repartition = 0.0;             ///< repartition checks and repartitions
  double ms_total = 0.0;                   ///< the step, plus refitNow's refits and checks since the last one
};

struct StepResult {
  std::vector<FlaggedPair> flagged;        ///< sorted by (body_a, region_a, body_b, region_b)
  std::vector<CandidatePair> candidates;   ///< see CandidatePair
  StepStats stats;
};

class SensorWorld {
 public:
  explicit SensorWorld(const SensorSettings& settings = {});  ///< validates the settings
  ~SensorWorld();
  SensorWorld(SensorWorld&&) noexcept;
  SensorWorld& operator=(SensorWorld&&) noexcept;
  SensorWorld(const SensorWorld&) = delete;
  SensorWorld& operator=(const SensorWorld&) = delete;

  /// Validates the mesh (psc::Error naming the problem) and adds it. Partitioning is deferred to
  /// the next step(), when the scene's particle budget is known.
  BodyId addBody(const BodyDesc& desc);
  /// Forgets the body. Throws psc::Error(InvalidArgument) for an unknown id.
  void removeBody(BodyId id);
  bool hasBody(BodyId id) const;
  std::vector<BodyId> bodyIds() const;  ///< ascending

  /// New views after the owner moved its memory (same vertex count; else psc::Error).
  void setPositions(BodyId id, const PositionView& positions, const PositionView& previous = {});
  void setMargin(BodyId id, double margin);
  /// Self-collision of one body: its vertices against its own triangles, within the self contact
  /// radius (selfRadius) plus motion_factor × selfMotion (with MotionBound::Radius: the vertex's
  /// motion against the body's own, so that a body moving as a whole does not meet itself at the
  /// radius its speed gives Bullet's test). A pair is never a candidate when the triangle holds
  /// the vertex, or when the two were closer than self_rest_exclusion × the self contact radius
  /// in the body's rest shape, i.e. its positions when self-collision was switched on (or the
  /// body added with it): what touches at rest is the surface itself, not a fold. Switching it on
  /// again takes the current positions as rest shape.
  void setSelfCollision(BodyId id, bool on);
  bool selfCollision(BodyId id) const;
  /// The body's self contact radius (selfContactRadius of its margin and rest shape); 0 when its
  /// self-collision is off. Self contacts should be made at this distance, not 2 × margin.
  double selfRadius(BodyId id) const;
  /// The body's mean displacement in the last step() over its vertices on triangles, the `mean` of
  /// psc::selfMotion that its self candidates were taken with; zero when its self-collision is off,
  /// before its first step with it, under MotionBound::Swept, or when its previous positions come
  /// in another scalar type (psc::selfMotion is then |d|). A self contact's radius is
  /// selfRadius + motion_factor × selfMotion(d, this), not Bullet's margins + 2·|d|.
  Vec3 selfMeanMotion(BodyId id) const;
  /// [beyond] The motion bound of one body pair with MotionBound::Radius: `ahead` = true hands the
  /// pair's exact test only what MotionBound::Ahead keeps (the pairs within the margins now and
  /// those the vertex and the triangle head into during the next ahead_steps steps) until the two
  /// bodies' grown boxes part; then the pair is back on the radius bound. For a pair whose contacts
  /// feed on the motion term of Bullet's radius (a runaway: psc::bullet does this when it sees
  /// one). Ignored with the other motion bounds and in the thesis's mode. Throws for unknown ids.
  void setPairAhead(BodyId a, BodyId b, bool ahead);
  bool pairAhead(BodyId a, BodyId b) const;
  /// The mesh itself changed (vertex count, triangles): rebuilds the topology and repartitions
  /// (at the next step(), which counts it in StepStats::repartitions and repartitionCount). A
  /// particle count given at addBody stays; a mesh with fewer vertices in triangles than that gets
  /// one particle a vertex.
  void replaceMesh(BodyId id, std::vector<Triangle> triangles, const PositionView& positions,
                   const PositionView& previous = {});

  /// Optional: refits the body's boxes for the coming step() now, and step() does not refit it
  /// again. Call it right after the owner wrote the body's positions for the step (e.g. right after
  /// Bullet's btSoftBody::predictMotion), while they are still in the cache: the refit is the one
  /// stage that reads every vertex (on 8 Bullet bodies of 50,000 vertices it took 5.4 ms a step
  /// this way against 6.3 ms in step(), after the other bodies had pushed them out). The
  /// positions must not change between this call and step(); setPositions(), setSelfCollision()
  /// and replaceMesh() cancel it (step() then refits as usual). Returns false, doing nothing, for
  /// a body step() has not partitioned yet or when bodies were added or removed since the last
  /// step (step() refits those itself). Throws like step() for a non-finite position, in which case
  /// step() refits the body again. The body's repartition check rides on this refit as on step()'s;
  /// the time and counts go into the next step's StepStats (ms_refit, ms_repartition).
  bool refitNow(BodyId id);

  /// Moves the particles until stable, flags region pairs, builds candidate pairs, and checks
  /// whether bodies need repartitioning. Deterministic.
  const StepResult& step();
  const StepResult& lastResult() const;

  /// μ between two bodies with the current margins (without the per-vertex motion term):
  /// μ = mu_edge_factor · max(ē_A, ē_B) + margin_A + margin_B.
  double mu(BodyId a, BodyId b) const;

  // --- inspection (after the body's first step) ---
  // After partitioning, the midphase keeps only what a step reads (chunks of triangles, no
  // one-ring or vertex-triangle lists, no per-vertex region): topology() and partition() rebuild
  // the full topology and Partition::region_of from it (O(M log M) on the first call after a step)
  // and keep them until the next step(), replaceMesh() or removeBody(), which the references do
  // not outlive. Not safe to call from two threads on one world at once, like the rest.
  const MeshTopology& topology(BodyId id) const;
  const Partition& partition(BodyId id) const;   ///< psc::Error before the first step
  std::vector<ParticleState> particles() const;  ///< all particles, by body then region
  std::size_t particleCount(BodyId id) const;
  std::size_t repartitionCount(BodyId id) const;  ///< times re-partitioned after the first
  /// Bytes the midphase keeps for this body: chunks, boxes, regions, particles, the full
  /// topology while it is alive and, with nearest_candidates, its vertices' last nearest triangles
  /// (no positions, no convex parts).
  std::size_t memoryBytes(BodyId id) const;
  const MeshReport& report(BodyId id) const;
  const SensorSettings& settings() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// A body's self contact radius: max(2 × margin, self_radius_edges × rest_mean_edge), where
/// rest_mean_edge is the mean edge length of its rest shape (edgeStats(...).mean). One definition
/// for the core, the Bullet plugin's self contacts and the demo's self truth.
double selfContactRadius(double margin, double rest_mean_edge, double self_radius_edges);

/// The length of a self pair's motion term for its vertex: min(|d|, |d − mean|), d the vertex's
/// displacement this step (position − previous position) and `mean` the body's mean displacement
/// over its vertices that are in triangles. Bullet's vertex–face test grows its radius by 2·|d|: a
/// body flying at speed would take its own neighbours for contacts. Against the body's mean, a
/// body moving as a whole has none, and a part moving towards the rest keeps its term (never more
/// than Bullet's, so Bullet's test accepts every self candidate within it). One definition for the
/// core's self candidates and the demo's self truth. (When a body's previous positions come in
/// another scalar type than its positions, the core takes mean = 0 for it: Bullet's term.)
inline double selfMotion(const Vec3& d, const Vec3& mean) { return std::min(d.norm(), (d - mean).norm()); }

}  // namespace psc
