#include "psc/world.h"

#include "body.h"
#include "bounds.h"
#include "candidates.h"
#include "thesis_mode.h"
#include "psc/error.h"
#include "psc/hash_grid.h"
#include "psc/repartition.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>
#include <sstream>

namespace psc {

using detail::Body;

namespace {

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

}  // namespace

struct SensorWorld::Impl {
  SensorSettings settings;
  std::map<BodyId, std::unique_ptr<Body>> bodies;  // ordered by id: deterministic iteration
  BodyId next_id = 0;
  bool membership_changed = false;
  StepResult result;
  /// What refitNow() did since the last step: its refit and repartition figures join the step's.
  StepStats ahead;

  // Particle arrays for one step, ordered by (body id, region).
  detail::Particles particles;
  std::vector<Index> p_dest;
  std::vector<Index> p_left;  // vertex each particle left last round (no_backtrack)
  std::vector<char> p_dirty;    // its pull may have changed since it last stayed put
  std::vector<char> p_movable;  // it may move this step (see step())
  std::vector<std::pair<Index, Vec3>> p_moved;  // particles moved last round, and where from
  std::vector<Index> near;
  /// A particle's one ring in its region, found through the chunks' triangles and kept while the
  /// particle stays on that vertex of that partition (most evaluations are of particles that stay).
  struct Ring {
    std::uint64_t partition = 0;  // Body::partition_number
    Index vertex = kInvalidIndex;
    std::vector<Index> vertices;  // ascending
  };
  std::vector<Ring> rings;  // per particle
  std::uint64_t partitions_made = 0;
  PointHashGrid grid;
  detail::ThesisScratch thesis;
  /// SensorWorld::setPairAhead: body pairs (first < second), sorted.
  std::vector<std::pair<BodyId, BodyId>> ahead_pairs;
  /// SensorSettings::nearest_candidates: each vertex's nearest triangles of the last step.
  detail::NearestSeeds nearest_seeds;
  std::size_t last_candidates = 0;  ///< the candidate list's length at the last step (CullParams)

  Body& get(BodyId id) {
    auto it = bodies.find(id);
    if (it == bodies.end()) throw Error(ErrorCode::InvalidArgument, "unknown body id " + std::to_string(id));
    return *it->second;
  }
  const Body& get(BodyId id) const { return const_cast<Impl*>(this)->get(id); }

  /// R_eff for this step (after the refit). Auto: twice the largest region box diagonal. Two
  /// regions that touch have their particles within the sum of their diameters, so touching
  /// regions always feel each other, and each particle only feels its neighbourhood.
  double rEff() const {
    double r = settings.r_eff;
    double max_region = 0.0, max_edge = 0.0, max_margin = 0.0;
    for (const auto& kv : bodies) {
      for (const detail::MotionBox& box : kv.second->region_box)
        if (box.hi.x() >= box.lo.x()) max_region = std::max(max_region, (box.hi - box.lo).norm());
      max_edge = std::max(max_edge, kv.second->mean_edge);
      max_margin = std::max(max_margin, kv.second->margin);
    }
    if (r == 0.0) r = 2.0 * max_region;
    // §5.1.3: a touching pair is only pulled together when R_eff exceeds μ.
    const double max_mu = settings.mu_edge_factor * max_edge + 2.0 * max_margin;
    return std::max(r, 1.01 * max_mu + 1e-12);
  }

  /// Whether the full topology and the partition's region_of stay alive after partitioning: the
  /// thesis's candidate sets and the four-direction walk read them every step. Otherwise the chunks
  /// are all the steps need (Body::topology).
  bool keepsSetup() const {
    return settings.flagging == Flagging::Sensors || settings.repartition.estimator == AreaEstimator::FourDirectionWalk;
  }

  /// Partitions b into `count` regions; returns whether that was a repartition (the body had a
  /// partition, or its mesh was replaced since).
  bool partitionBody(Body& b, std::size_t count);
  void preparePartitions(StepStats& stats);
  void refitAndCheck(Body& b, StepStats& stats);
  /// Whether the refit carries b's self-collision part (the rest-shape bound and the self motion
  /// term): what the self-collision cull reads with MotionBound::Radius in the default midphase.
  bool restFitOn(const Body& b) const {
    return b.selfCollides() && settings.motion_bound != MotionBound::Swept && settings.flagging != Flagging::Sensors;
  }
  /// SensorSettings::meeting_pairs in effect: with MotionBound::Radius in the default midphase.
  bool meetingPairs() const {
    return settings.meeting_pairs && settings.motion_bound == MotionBound::Radius && settings.flagging != Flagging::Sensors;
  }
  void moveParticles(StepStats& stats, double r_eff);
  const std::vector<Index>& ringOf(std::size_t particle, const Body& b, Index region, Index v);
};

bool SensorWorld::Impl::partitionBody(Body& b, std::size_t count) {
  const bool again = b.partitioned || b.replaced;
  b.replaced = false;
  const MeshTopology& topology = b.fullTopology();
  b.partition = partitionLBG(topology, b.positions, count, settings.partition);
  // The thesis's candidate sets need per-region lists; the bounds layer needs only the chunks.
  b.regions = settings.flagging == Flagging::Sensors
                  ? detail::buildRegionLists(topology, b.partition.region_of, b.partition.regionCount())
                  : detail::RegionLists{};
  b.particle_vertex = b.partition.seed_vertex;
  b.mean_edge = edgeStats(topology, b.positions).mean;
  b.chunks = detail::buildChunks(topology, b.positions, b.partition.region_of, b.partition.regionCount(),
                                 chunkVerticesFor(settings, b.vertices_in_triangles));
  b.rest_fit.reset();
  // The repartition check compares with what the same refit measures now (A* and the longest edge).
  b.chunk_area_ref.clear();  // the new chunks' areas become the reference
  detail::refitBounds(b, {detail::Measure::Full, settings.repartition.area_sample_chunks},
                      settings.motion_bound == MotionBound::Swept, restFitOn(b), meetingPairs());
  b.max_edge = b.shape.max_edge;
  b.chunk_area_ref = std::move(b.shape.chunk_area);
  b.shape.chunk_area = {};
  const std::vector<double> areas =
      settings.repartition.estimator == AreaEstimator::TrueArea
          ? b.shape.region_area
          : regionAreas(topology, b.positions, b.partition, b.particle_vertex, settings.repartition.estimator);
  b.area_star = areas.empty() ? 0.0 : *std::max_element(areas.begin(), areas.end());
  b.budget = count;
  b.partitioned = true;
  b.partition_number = ++partitions_made;
  if (!keepsSetup()) b.dropSetup();
  // Bodies are checked on staggered steps so the O(M) checks do not all land on one step.
  b.steps_since_check = static_cast<int>(b.id % static_cast<BodyId>(settings.repartition.check_every));
  if (again) ++b.repartitions;
  return again;
}

namespace {

/// Runs f() on body b's input; an Error that names no body is thrown again naming b (its label in
/// the message, its id in Error::body()), so that a caller can leave that body out.
template <class F>
void forBody(const Body& b, F&& f) {
  try {
    f();
  } catch (const Error& e) {
    if (e.body() != Error::kNoBody) throw;
    const std::string label = b.label();
    throw Error(e.code(), e.message().rfind(label, 0) == 0 ? e.message() : label + ": " + e.message(), b.id);
  }
}

}  // namespace

void SensorWorld::Impl::preparePartitions(StepStats& stats) {
  bool any_new = membership_changed;
  for (const auto& kv : bodies) any_new = any_new || !kv.second->partitioned;
  if (!any_new) return;
  std::vector<BudgetBody> budget_in;
  budget_in.reserve(bodies.size());
  for (auto& kv : bodies) {
    Body& b = *kv.second;
    if (!b.parts)
      forBody(b, [&] {
        b.parts = std::make_shared<const ConvexParts>(decomposeConvex(b.fullTopology(), b.positions, settings.decomposition));
      });
    budget_in.push_back({*b.parts, b.particle_override});
  }
  const std::vector<std::size_t> budget = particleBudget(budget_in);
  std::size_t k = 0;
  for (auto& kv : bodies) {
    Body& b = *kv.second;
    const std::size_t cap = b.particle_override > 0
                                ? b.vertices_in_triangles
                                : std::max<std::size_t>(1, b.vertices_in_triangles / settings.min_region_vertices);
    std::size_t count = std::clamp<std::size_t>(budget[k++], 1, cap);
    // The thesis's LBG doubles the codebook: with any_count off the count is a power of two, the
    // largest one within the budget.
    if (!settings.partition.any_count)
      while ((count & (count - 1)) != 0) count &= count - 1;
    if (!b.partitioned || count != b.budget) {
      bool again = false;
      forBody(b, [&] { again = partitionBody(b, count); });
      if (again) ++stats.repartitions;
    }
  }
  membership_changed = false;
}

void SensorWorld::Impl::refitAndCheck(Body& b, StepStats& stats) {
  const RepartitionSettings& rs = settings.repartition;
  const bool check = rs.enabled && b.deformable && ++b.steps_since_check >= rs.check_every;
  // The check's figures come with the refit: the regions' areas from a sample of their chunks,
  // measured after the pass; the edge trigger (the thesis's mode only) needs every triangle's edges.
  const bool edges = settings.flagging == Flagging::Sensors && rs.edge_stretch_trigger > 0.0;
  const detail::Measure measure{!check ? detail::Measure::None : edges ? detail::Measure::Full : detail::Measure::Sampled,
                                rs.area_sample_chunks};
  auto t = Clock::now();
  detail::refitBounds(b, measure, settings.motion_bound == MotionBound::Swept, restFitOn(b), meetingPairs());
  stats.ms_refit += msSince(t);
  if (!check) return;
  t = Clock::now();
  b.steps_since_check = 0;
  // The edge trigger refreshes μ, which decides only in the thesis's flag-only mode: the default
  // midphase's boxes and distances do not depend on it, and there a repartition for one stretched
  // edge changed nothing but cost (about 40 ms per 50,000-vertex body; docs/METHOD.md §7).
  bool trigger = edges && b.shape.max_edge > rs.edge_stretch_trigger * b.max_edge;
  if (!trigger) {
    const std::vector<double> areas =
        rs.estimator == AreaEstimator::TrueArea
            ? b.shape.region_area
            : regionAreas(b.fullTopology(), b.positions, b.fullPartition(), b.particle_vertex, rs.estimator);
    trigger = !areas.empty() && *std::max_element(areas.begin(), areas.end()) > rs.area_trigger * b.area_star;
  }
  if (trigger) {
    partitionBody(b, b.budget);
    ++stats.repartitions;
  }
  stats.ms_repartition += msSince(t);
}

const std::vector<Index>& SensorWorld::Impl::ringOf(std::size_t particle, const Body& b, Index region, Index v) {
  Ring& ring = rings[particle];
  if (ring.partition == b.partition_number && ring.vertex == v) return ring.vertices;
  ring.partition = b.partition_number;
  ring.vertex = v;
  ring.vertices.clear();
  b.chunks.forEachTriangleOf(v, [&](Index, const Triangle& tri) {
    for (Index u : tri)
      if (u != v && b.chunks.region_of[b.chunks.chunkOf(u)] == region) ring.vertices.push_back(u);
  });
  std::sort(ring.vertices.begin(), ring.vertices.end());
  ring.vertices.erase(std::unique(ring.vertices.begin(), ring.vertices.end()), ring.vertices.end());
  return ring.vertices;
}

void SensorWorld::Impl::moveParticles(StepStats& stats, double r_eff) {
  const std::size_t n = particles.pos.size();
  // A candidate vertex lies up to one (stretched) edge from its particle. Outside the thesis's mode
  // no edge trigger holds edges below that stretch: a longer edge only makes a hop miss a puller,
  // and the default midphase's decisions hold whatever the particles' places.
  double slack = 0.0;
  for (const auto& kv : bodies) slack = std::max(slack, kv.second->max_edge);
  slack *= std::max(1.0, settings.repartition.edge_stretch_trigger);
  const double reach = r_eff + slack;
  const double reach2 = reach * reach;
  const double r_eff2 = r_eff * r_eff;
  const double floor2 = 1e-12 * r_eff2;  // Φ stays finite when two particles coincide

  p_dest.resize(n);
  rings.resize(n);
  p_left.assign(n, kInvalidIndex);
  p_dirty.assign(n, 1);
  p_moved.clear();
  const bool until_stable = settings.flagging == Flagging::Sensors || settings.rounds_per_step == 0;
  const int rounds = until_stable ? settings.max_rounds : std::min(settings.rounds_per_step, settings.max_rounds);
  for (int round = 0; round < rounds; ++round) {
    grid.build(particles.pos, reach);
    // A particle that stayed put last round decides the same again unless a particle within its
    // reach moved (from or to a place within reach): only those are evaluated again. Exact.
    if (round > 0) {
      std::fill(p_dirty.begin(), p_dirty.end(), 0);
      for (const auto& [j, from] : p_moved) {
        p_dirty[j] = 1;
        for (const Vec3& at : {from, particles.pos[j]})
          grid.forEachCandidate(at, [&](Index k) {
            if ((particles.pos[k] - at).squaredNorm() < reach2) p_dirty[k] = 1;
          });
      }
      p_moved.clear();
    }
    std::size_t moved = 0;
    for (std::size_t i = 0; i < n; ++i) {
      Body& b = *particles.body[i];
      const Index region = particles.region[i];
      const Index cur = b.particle_vertex[region];
      p_dest[i] = cur;
      if (!p_dirty[i] || !p_movable[i]) continue;
      near.clear();
      grid.forEachCandidate(particles.pos[i], [&](Index j) {
        if (particles.body[j] != &b && (particles.pos[j] - particles.pos[i]).squaredNorm() < reach2) near.push_back(j);
      });
      if (near.empty()) continue;  // no pull: the particle stays
      const auto phi = [&](const Vec3& q) {
        double sum = 0.0;
        for (Index j : near) {
          const double d2 = (q - particles.pos[j]).squaredNorm();
          if (d2 < r_eff2) sum += 1.0 / std::max(d2, floor2);
        }
        return sum;
      };
      double best = phi(particles.pos[i]);
      // Neighbours are sorted ascending and only a strictly larger pull moves the particle:
      // ties stay, then lowest index, so runs are deterministic.
      for (Index u : ringOf(i, b, region, cur)) {
        if (u == p_left[i]) continue;
        const double f = phi(b.positions[u]);
        if (f > best) {
          best = f;
          p_dest[i] = u;
        }
      }
      if (p_dest[i] != cur) ++moved;
    }
    stats.rounds = round + 1;
    if (moved == 0) return;
    stats.particle_moves += moved;
    // Jacobi: every destination was chosen from the same positions; now all move at once.
    for (std::size_t i = 0; i < n; ++i) {
      Index& at = particles.body[i]->particle_vertex[particles.region[i]];
      // Two particles approaching head-on along parallel paths pass each other and, under pure
      // Jacobi updates, swap back forever (seen on interlocking U shapes): with no_backtrack a
      // particle never returns to the vertex it just left within one step.
      if (p_dest[i] == at) continue;
      p_moved.emplace_back(static_cast<Index>(i), particles.pos[i]);
      if (settings.no_backtrack) p_left[i] = at;
      at = p_dest[i];
      particles.pos[i] = particles.body[i]->positions[p_dest[i]];
    }
  }
  // Stopping after rounds_per_step is the plan, not a cap: the particles go on next step.
  if (until_stable) stats.round_cap_hits = 1;
}

// ------------------------------------------------------------------------------------------------

SensorWorld::SensorWorld(const SensorSettings& settings) : impl_(std::make_unique<Impl>()) {
  validate(settings);
  impl_->settings = settings;
}
SensorWorld::~SensorWorld() = default;
SensorWorld::SensorWorld(SensorWorld&&) noexcept = default;
SensorWorld& SensorWorld::operator=(SensorWorld&&) noexcept = default;

namespace {

[[noreturn]] void badMargin(const std::string& label, double margin) {
  std::ostringstream s;
  s << label << ": margin = " << margin << " must be finite, not negative and at most " << kMaxCoordinate
    << " (the coordinates' range)";
  throw Error(ErrorCode::InvalidSettings, s.str());
}

/// A margin the midphase can square and sum: within [0, kMaxCoordinate] (a review's finding, stop
/// 46: above about 1e154 the squared radii overflowed, one pair came out twice and then the hash
/// grid's cell size was infinite, with no body named).
bool validMargin(double margin) { return std::isfinite(margin) && margin >= 0.0 && margin <= kMaxCoordinate; }

// Validates a body description completely and builds its topology; nothing is partitioned yet.
/// `fit_particles`: a particle count beyond the vertices that lie in triangles is kept and used as
/// that many (replaceMesh keeps a count given at addBody, and a finer mesh later gets it all)
/// instead of refused.
std::unique_ptr<Body> makeBody(BodyId id, const BodyDesc& desc, bool fit_particles = false) {
  auto b = std::make_unique<Body>();
  b->id = id;
  b->name = desc.name;
  const std::string label = b->label();
  if (!validMargin(desc.margin)) badMargin(label, desc.margin);
  try {
    b->topology.emplace(desc.triangles, desc.positions.size());
  } catch (const Error& e) {
    throw Error(e.code(), label + ": " + std::string(e.what()).substr(std::string(toString(e.code())).size() + 2));
  }
  b->vertex_count = desc.positions.size();
  b->report = validate(*b->topology, desc.positions, label);
  if (b->report.degenerate_triangles == b->topology->triangleCount())
    throw Error(ErrorCode::InvalidMesh, label + ": all " + std::to_string(b->topology->triangleCount()) +
                                            " triangles are degenerate (zero area)");
  if (!desc.previous.empty()) {
    if (desc.previous.size() != desc.positions.size())
      throw Error(ErrorCode::InvalidArgument, label + ": the previous-position view has " +
                                                  std::to_string(desc.previous.size()) + " vertices, not " +
                                                  std::to_string(desc.positions.size()));
    checkFinite(desc.previous, label + " (previous positions)");
  }
  for (Index v = 0; v < b->topology->vertexCount(); ++v)
    if (!b->topology->vertexTriangles(v).empty()) ++b->vertices_in_triangles;
  if (desc.particles > b->vertices_in_triangles && !fit_particles)
    throw Error(ErrorCode::InvalidSettings, label + ": particles = " + std::to_string(desc.particles) +
                                                " exceeds the " + std::to_string(b->vertices_in_triangles) +
                                                " vertices that lie in triangles");
  if (desc.parts && desc.parts->part_of.size() != desc.positions.size())
    throw Error(ErrorCode::InvalidArgument, label + ": the given convex parts label " +
                                                std::to_string(desc.parts->part_of.size()) + " vertices, not " +
                                                std::to_string(desc.positions.size()));
  if (desc.parts) {
    // Checked here, naming the body, rather than by the particle budget at the next step (a review's
    // finding, stop 46: that error named the body's index in the budget and every step threw).
    const ConvexParts& cp = *desc.parts;
    if (cp.parts.empty()) throw Error(ErrorCode::InvalidArgument, label + ": the given convex parts are empty");
    for (std::size_t k = 0; k < cp.parts.size(); ++k)
      if (!(std::isfinite(cp.parts[k].radius) && cp.parts[k].radius >= 0.0 && cp.parts[k].center.allFinite()))
        throw Error(ErrorCode::InvalidArgument, label + ": convex part " + std::to_string(k) +
                                                    " has a non-finite or negative radius or centre");
    for (std::size_t v = 0; v < cp.part_of.size(); ++v)
      if (cp.part_of[v] >= cp.parts.size())
        throw Error(ErrorCode::InvalidArgument, label + ": vertex " + std::to_string(v) + " is labelled part " +
                                                    std::to_string(cp.part_of[v]) + " of " +
                                                    std::to_string(cp.parts.size()));
  }
  b->positions = desc.positions;
  b->previous = desc.previous;
  b->margin = desc.margin;
  b->particle_override = desc.particles;  // used at most vertices_in_triangles (preparePartitions)
  b->deformable = desc.deformable;
  b->parts = desc.parts;
  if (desc.self_collision) {
    b->rest = detail::RestShape(desc.positions);
    b->rest_fit.reset();
    b->rest_mean_edge = edgeStats(*b->topology, desc.positions).mean;
  }
  return b;
}

}  // namespace

namespace {
void checkSelfCollisionMode(const SensorSettings& settings, const std::string& label) {
  if (settings.flagging == Flagging::Sensors)
    throw Error(ErrorCode::InvalidSettings, label + ": self-collision needs flagging = SensorsAndBounds or Bounds, "
                                                    "not Sensors (the thesis's flag-only mode)");
}
}  // namespace

BodyId SensorWorld::addBody(const BodyDesc& desc) {
  const std::string label = desc.name.empty() ? "addBody" : "body '" + desc.name + "'";
  if (desc.self_collision) checkSelfCollisionMode(impl_->settings, label);
  if (!impl_->settings.partition.any_count && desc.particles > 0 && (desc.particles & (desc.particles - 1)) != 0)
    throw Error(ErrorCode::InvalidSettings, label + ": particles = " + std::to_string(desc.particles) +
                                                " is not a power of two, which partition.any_count off needs");
  const BodyId id = impl_->next_id;
  impl_->bodies.emplace(id, makeBody(id, desc));
  ++impl_->next_id;
  impl_->membership_changed = true;
  return id;
}

void SensorWorld::removeBody(BodyId id) {
  impl_->get(id);
  impl_->bodies.erase(id);
  impl_->membership_changed = true;
  auto& pairs = impl_->ahead_pairs;
  pairs.erase(std::remove_if(pairs.begin(), pairs.end(), [id](const auto& p) { return p.first == id || p.second == id; }),
              pairs.end());
}

void SensorWorld::setPairAhead(BodyId a, BodyId b, bool ahead) {
  impl_->get(a);
  impl_->get(b);
  if (a == b) throw Error(ErrorCode::InvalidArgument, "setPairAhead: a body pair needs two bodies, got " + std::to_string(a) + " twice");
  const std::pair<BodyId, BodyId> key(std::min(a, b), std::max(a, b));
  auto& pairs = impl_->ahead_pairs;
  const auto at = std::lower_bound(pairs.begin(), pairs.end(), key);
  const bool has = at != pairs.end() && *at == key;
  if (ahead && !has) pairs.insert(at, key);
  if (!ahead && has) pairs.erase(at);
}

bool SensorWorld::pairAhead(BodyId a, BodyId b) const {
  impl_->get(a);
  impl_->get(b);
  const std::pair<BodyId, BodyId> key(std::min(a, b), std::max(a, b));
  return std::binary_search(impl_->ahead_pairs.begin(), impl_->ahead_pairs.end(), key);
}

bool SensorWorld::hasBody(BodyId id) const { return impl_->bodies.count(id) != 0; }

std::vector<BodyId> SensorWorld::bodyIds() const {
  std::vector<BodyId> ids;
  for (const auto& kv : impl_->bodies) ids.push_back(kv.first);
  return ids;
}

void SensorWorld::setPositions(BodyId id, const PositionView& positions, const PositionView& previous) {
  Body& b = impl_->get(id);
  if (positions.size() != b.vertex_count || positions.empty())
    throw Error(ErrorCode::InvalidArgument, b.label() + ": setPositions got " + std::to_string(positions.size()) +
                                                " vertices but the mesh has " + std::to_string(b.vertex_count) +
                                                " (use replaceMesh)");
  if (!previous.empty() && previous.size() != positions.size())
    throw Error(ErrorCode::InvalidArgument, b.label() + ": the previous-position view has " +
                                                std::to_string(previous.size()) + " vertices, not " +
                                                std::to_string(positions.size()));
  b.positions = positions;
  b.previous = previous;
  b.refit_ahead = false;
}

void SensorWorld::setMargin(BodyId id, double margin) {
  Body& b = impl_->get(id);
  if (!validMargin(margin)) badMargin(b.label(), margin);
  b.margin = margin;
}

void SensorWorld::setSelfCollision(BodyId id, bool on) {
  Body& b = impl_->get(id);
  if (on) checkSelfCollisionMode(impl_->settings, b.label());
  if (on) checkFinite(b.positions, b.label());
  b.rest = on ? detail::RestShape(b.positions) : detail::RestShape{};
  b.rest_fit.reset();
  b.refit_ahead = false;
  b.rest_mean_edge = on ? edgeStats(b.fullTopology(), b.positions).mean : 0.0;
}

bool SensorWorld::selfCollision(BodyId id) const { return impl_->get(id).selfCollides(); }

double SensorWorld::selfRadius(BodyId id) const {
  const Body& b = impl_->get(id);
  return b.selfCollides() ? selfContactRadius(b.margin, b.rest_mean_edge, impl_->settings.self_radius_edges) : 0.0;
}

Vec3 SensorWorld::selfMeanMotion(BodyId id) const {
  const Body& b = impl_->get(id);
  return b.selfCollides() && b.rest_fit && b.rest_fit->filled ? b.rest_fit->mean_motion : Vec3::Zero();
}

double selfContactRadius(double margin, double rest_mean_edge, double self_radius_edges) {
  return std::max(2.0 * margin, self_radius_edges * rest_mean_edge);
}

void SensorWorld::replaceMesh(BodyId id, std::vector<Triangle> triangles, const PositionView& positions,
                              const PositionView& previous) {
  Body& old = impl_->get(id);
  BodyDesc desc;
  desc.triangles = std::move(triangles);
  desc.positions = positions;
  desc.previous = previous;
  desc.margin = old.margin;
  // A count given at addBody stays; a coarser mesh with fewer vertices in triangles gets one a vertex.
  desc.particles = old.particle_override;
  desc.deformable = old.deformable;
  desc.self_collision = old.selfCollides();  // the new mesh's positions become its rest shape
  desc.name = old.name;
  std::unique_ptr<Body> fresh = makeBody(id, desc, true);  // the old body stays if this throws
  fresh->repartitions = old.repartitions;  // the next step's partition of it counts as one
  fresh->replaced = true;
  impl_->bodies[id] = std::move(fresh);
  impl_->membership_changed = true;
}

bool SensorWorld::refitNow(BodyId id) {
  Impl& w = *impl_;
  Body& b = w.get(id);
  // A new body or a changed membership: step() partitions first (and a partition refits itself).
  if (!b.partitioned || w.membership_changed) return false;
  b.refit_ahead = false;
  forBody(b, [&] { w.refitAndCheck(b, w.ahead); });  // throws for a non-finite vertex; step() then refits and throws again
  b.refit_ahead = true;
  return true;
}

const StepResult& SensorWorld::step() {
  Impl& w = *impl_;
  const auto t_start = Clock::now();
  StepResult& res = w.result;
  res.flagged.clear();
  res.candidates.clear();
  res.stats = StepStats{};
  StepStats& st = res.stats;

  // What inspection rebuilt since the last step goes again (SensorWorld::topology, partition).
  if (!w.keepsSetup())
    for (auto& kv : w.bodies)
      if (kv.second->partitioned) kv.second->dropSetup();
  auto t = Clock::now();
  w.preparePartitions(st);
  st.ms_repartition = msSince(t);
  for (auto& kv : w.bodies) {
    Body& b = *kv.second;
    if (b.refit_ahead)
      b.refit_ahead = false;  // refitNow() did it, closer to where the positions were written
    else
      forBody(b, [&] { w.refitAndCheck(b, st); });
  }
  st.ms_refit += w.ahead.ms_refit;
  st.ms_repartition += w.ahead.ms_repartition;
  st.repartitions += w.ahead.repartitions;
  const double ms_ahead = w.ahead.ms_refit + w.ahead.ms_repartition;  // counted in ms_total too
  w.ahead = StepStats{};

  st.bodies = w.bodies.size();
  std::vector<Body*> ordered;
  for (auto& kv : w.bodies) ordered.push_back(kv.second.get());
  detail::CullParams params;
  params.swept = w.settings.motion_bound == MotionBound::Swept;
  params.meeting = w.meetingPairs();
  params.motion_factor = params.swept ? 0.0 : w.settings.motion_factor;
  params.ahead_steps = w.settings.motion_bound == MotionBound::Ahead ? w.settings.ahead_steps : 0.0;
  params.use_sensors = w.settings.flagging == Flagging::SensorsAndBounds;
  params.self_rest_exclusion = w.settings.self_rest_exclusion;
  params.self_radius_edges = w.settings.self_radius_edges;
  params.self_rest_bound = w.settings.self_rest_bound;
  params.nearest = w.settings.nearest_candidates && !params.swept && !params.meeting;
  if (params.nearest) params.seeds = &w.nearest_seeds;
  // [beyond] In the default mode a particle only serves the sensor decision of its region's pairs,
  // which exist only where the region's box reaches another body's: the other particles stay put
  // (and still pull).
  // Pairing the bodies and finding the regions near other bodies is flagging work: timed into
  // ms_flagging (it was in no stage's time before stop 47, only in ms_total).
  t = Clock::now();
  const detail::BodyPairs body_pairs = w.settings.flagging == Flagging::Sensors
                                           ? detail::BodyPairs{}
                                           : detail::overlappingBodies(ordered, params);
  if (!w.ahead_pairs.empty()) {
    // A pair on the Ahead bound goes back to the radius once its bodies' grown boxes part.
    // body_pairs are sorted and `ordered` ascends by id, so `still` comes out sorted.
    std::vector<std::pair<BodyId, BodyId>> still;
    for (const auto& [i, j] : body_pairs) {
      const std::pair<BodyId, BodyId> key(ordered[i]->id, ordered[j]->id);
      if (std::binary_search(w.ahead_pairs.begin(), w.ahead_pairs.end(), key)) still.push_back(key);
    }
    w.ahead_pairs.swap(still);
    params.ahead_pairs = &w.ahead_pairs;
    params.pair_ahead_steps = w.settings.ahead_steps;
  }
  const std::vector<std::vector<char>> near = params.use_sensors
                                                  ? detail::regionsNearOtherBodies(ordered, body_pairs, params)
                                                  : std::vector<std::vector<char>>{};
  const double ms_pairing = msSince(t);
  detail::Particles& ps = w.particles;
  ps.clear();
  w.p_movable.clear();
  for (std::size_t i = 0; i < ordered.size(); ++i) {
    Body& b = *ordered[i];
    for (Index r = 0; r < b.regionCount(); ++r) {
      ps.add(&b, r, b.positions[b.particle_vertex[r]]);
      w.p_movable.push_back(near.empty() || near[i][r]);
    }
  }
  st.particles = ps.size();
  if (st.particles == 0) {
    st.ms_total = msSince(t_start) + ms_ahead;
    return res;
  }
  const double r_eff = w.rEff();
  st.r_eff = r_eff;

  // Flagging::Bounds is the ablation with the sensor stage switched off: the particles stay put.
  if (w.settings.flagging != Flagging::Bounds) {
    t = Clock::now();
    w.moveParticles(st, r_eff);
    st.ms_sensors = msSince(t);
  }

  t = Clock::now();
  if (w.settings.flagging == Flagging::Sensors) {
    // The thesis's flag-only mode: particles closer than μ flag regions; candidate sets are the
    // flagged regions (+ ring).
    detail::flagByParticles(ps, w.settings, r_eff, w.grid, res.flagged, st);
    st.ms_flagging = msSince(t);
    if (w.settings.build_candidates) {
      t = Clock::now();
      detail::thesisCandidates(res.flagged, [&](BodyId id) -> const Body& { return w.get(id); }, w.settings,
                               w.thesis, res.candidates, st);
      st.ms_candidates = msSince(t);
    }
  } else {
    params.last_candidates = w.last_candidates;
    detail::cullAndCollect(ordered, body_pairs, params, res.flagged, res.candidates, st);
    w.last_candidates = res.candidates.size();
    std::sort(res.flagged.begin(), res.flagged.end(), detail::flaggedLess);
    st.ms_flagging = msSince(t) - st.ms_candidates + ms_pairing;
    st.candidate_pairs = res.candidates.size();
    for (const CandidatePair& c : res.candidates) st.self_candidate_pairs += c.vertex_body == c.triangle_body;
    if (!w.settings.build_candidates) res.candidates.clear();
  }
  st.flagged_pairs = res.flagged.size();
  for (const FlaggedPair& f : res.flagged) {
    if (f.by_sensors) ++st.flagged_by_sensors;
    else ++st.flagged_by_bounds_only;
  }
  st.ms_total = msSince(t_start) + ms_ahead;
  return res;
}

const StepResult& SensorWorld::lastResult() const { return impl_->result; }

double SensorWorld::mu(BodyId a, BodyId b) const {
  const Body& ba = impl_->get(a);
  const Body& bb = impl_->get(b);
  return impl_->settings.mu_edge_factor * std::max(ba.mean_edge, bb.mean_edge) + ba.margin + bb.margin;
}

const MeshTopology& SensorWorld::topology(BodyId id) const { return impl_->get(id).fullTopology(); }

const Partition& SensorWorld::partition(BodyId id) const {
  Body& b = impl_->get(id);
  if (!b.partitioned) throw Error(ErrorCode::InvalidArgument, b.label() + " has not been partitioned yet (call step())");
  return b.fullPartition();
}

std::vector<ParticleState> SensorWorld::particles() const {
  std::vector<ParticleState> out;
  for (const auto& kv : impl_->bodies)
    for (Index r = 0; r < kv.second->regionCount(); ++r) out.push_back({kv.first, r, kv.second->particle_vertex[r]});
  return out;
}

std::size_t SensorWorld::particleCount(BodyId id) const { return impl_->get(id).regionCount(); }
std::size_t SensorWorld::repartitionCount(BodyId id) const { return impl_->get(id).repartitions; }

std::size_t SensorWorld::memoryBytes(BodyId id) const {
  const Body& b = impl_->get(id);
  return sizeof(Body) + (b.topology ? b.topology->bytes() : 0) + b.regions.bytes() + b.partition.region_of.capacity() * sizeof(Index) +
         b.partition.seed_vertex.capacity() * sizeof(Index) +
         b.partition.code_vectors.capacity() * sizeof(b.partition.code_vectors[0]) +
         b.particle_vertex.capacity() * sizeof(Index) + b.chunks.bytes() +
         (b.chunk_box.capacity() + b.region_box.capacity()) * sizeof(detail::MotionBox) +
         b.chunk_own.capacity() * sizeof(detail::OwnBox) + b.chunk_area_ref.capacity() * sizeof(double) +
         b.rest.bytes() + (b.rest_fit ? sizeof(detail::RestFit) + b.rest_fit->bytes() : 0) +
         impl_->nearest_seeds.bytes(id);
}

const MeshReport& SensorWorld::report(BodyId id) const { return impl_->get(id).report; }
const SensorSettings& SensorWorld::settings() const { return impl_->settings; }

}  // namespace psc
