#include "installation.h"

#include "dispatcher_access.h"
#include "exact_stage.h"
#include "psc/error.h"
#include "psc/bullet/solver.h"

#include <BulletCollision/BroadphaseCollision/btOverlappingPairCache.h>
#include <BulletCollision/CollisionDispatch/btCollisionDispatcher.h>
#include <BulletSoftBody/btSoftRigidDynamicsWorld.h>

#include <algorithm>
#include <cassert>
#include <chrono>
#include <iterator>
#include <limits>
#include <string>
#include <tuple>
#include <utility>

namespace psc::bullet {
namespace {

constexpr int kSoft = SOFTBODY_SHAPE_PROXYTYPE;

/// How the plugin tells that Bullet has started a new internal step. The sensors must step exactly
/// once per internal (sub)step, after btSoftBody::predictMotion (m_x predicted, m_q previous) and
/// before the step's first soft-soft pair is collided; a second dispatch in the same step (from the
/// internal tick callback, or performDiscreteCollisionDetection() between steps) must not step them
/// again. Bullet 3.24 gives a plugin installed on an existing world no per-world hook at that
/// moment (docs/BULLET.md, "Once per step"): actions run once per step but after the dispatch, so a
/// later dispatch would look like a new step; the pre-tick callback runs before predictMotion and
/// is a single slot the program owns; the soft-body solver, which sees predictMotion, is fixed when
/// the world is built; BT_PROFILE zones reach only a process-wide hook. What Bullet does give:
/// btDiscreteDynamicsWorld::internalSingleStepSimulation sets btDispatcherInfo::m_stepCount to 0
/// after predictUnconstraintMotion and before the dispatch, on every internal step, and Bullet 3.24
/// never reads it. The plugin writes kSensed there once it has stepped the sensors, so
/// "m_stepCount != kSensed" means exactly "a new step has predicted its motion and the sensors have
/// not seen it yet". The value spells "psc!". A program that writes m_stepCount itself during a
/// step would make the sensors step again within it.
constexpr int kSensed = 0x70736321;

btCollisionDispatcher& collisionDispatcherOf(btSoftRigidDynamicsWorld& world) {
  auto* dispatcher = dynamic_cast<btCollisionDispatcher*>(world.getDispatcher());
  if (dispatcher == nullptr)
    throw psc::Error(psc::ErrorCode::InvalidArgument,
                     "psc::bullet::install: the world's dispatcher is not a btCollisionDispatcher");
  return *dispatcher;
}

double millisecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

/// StepResult::candidates is sorted by (vertex_body, triangle_body), so the pairs of one
/// direction of one body pair are a contiguous run.
std::pair<const psc::CandidatePair*, const psc::CandidatePair*> candidatesOf(
    const std::vector<psc::CandidatePair>& candidates, psc::BodyId vertex_body, psc::BodyId triangle_body) {
  const auto key = std::make_pair(vertex_body, triangle_body);
  const auto less = [](const psc::CandidatePair& c, const std::pair<psc::BodyId, psc::BodyId>& k) {
    return std::tie(c.vertex_body, c.triangle_body) < std::tie(k.first, k.second);
  };
  const auto greater = [](const std::pair<psc::BodyId, psc::BodyId>& k, const psc::CandidatePair& c) {
    return std::tie(k.first, k.second) < std::tie(c.vertex_body, c.triangle_body);
  };
  const auto first = std::lower_bound(candidates.begin(), candidates.end(), key, less);
  const auto last = std::upper_bound(first, candidates.end(), key, greater);
  const psc::CandidatePair* base = candidates.data();
  return {base + (first - candidates.begin()), base + (last - candidates.begin())};
}

/// The core's settings for this plugin. Continuous's crossing test needs, besides Bullet's radius,
/// every pair that meets during the step: with the radius bound it asks the core for both
/// (SensorSettings::meeting_pairs). Robust with ContactSet::NearestFace needs only each node's nearest faces: Robust accepts every pair within
/// the radius, so the nearest accepted contact is among them (SensorSettings::nearest_candidates).
/// Bullet's test refuses small faces, where a farther face could give the node its contact: it
/// gets every candidate.
psc::SensorSettings coreSettings(const Settings& settings) {
  psc::SensorSettings core = settings.sensors;
  if (settings.contacts == ContactSet::NearestFace && settings.exact == ExactTest::Robust) core.nearest_candidates = true;
  if (settings.exact == ExactTest::Continuous) core.meeting_pairs = true;
  return core;
}

/// Room in each body's m_scontacts, before the exact stage makes its first contact, for every
/// contact its candidates can make this step (one at most per candidate; `candidates` sorted by
/// vertex body). Left to itself Bullet's array doubles as it fills, copying into a new block while
/// the old one is still held: on a pile whose contacts grow from step to step (8 tori x 8,000
/// vertices: 1.5k candidates a step at step 50, 1.8M at step 190) that held up to twice the
/// contacts' bytes between steps and three times during a growth. An empty array short of room is
/// freed first, then sized to this step's need, an eighth more and twice its growth since the last
/// step (`last_need`: each body's need then, by id; replaced by this step's): a growing array is not
/// taken anew every step (a new block costs the allocator's system calls, brk and munmap, which
/// took milliseconds at times on a virtual machine: with an eighth alone this function took 0.1–0.5
/// ms a step on 8 tori x 50,000 vertices as they settled, and 4–12 ms in one step of every run;
/// docs/DECISIONS.md "Stop 42"), one that stopped growing keeps an eighth.
void reserveContacts(const std::vector<psc::CandidatePair>& candidates, const detail::BodyRegistry& registry,
                     std::vector<std::pair<psc::BodyId, std::size_t>>& last_need) {
  std::vector<std::pair<psc::BodyId, std::size_t>> need_now;
  for (auto run = candidates.begin(); run != candidates.end();) {
    const psc::BodyId id = run->vertex_body;
    const auto end = std::upper_bound(run, candidates.end(), id, [](psc::BodyId b, const psc::CandidatePair& c) {
      return b < c.vertex_body;
    });
    btSoftBody* body = registry.bodyOf(id);
    const auto need = static_cast<std::size_t>(end - run);
    run = end;
    if (body == nullptr) continue;
    need_now.emplace_back(id, need);
    btAlignedObjectArray<btSoftBody::SContact>& list = body->m_scontacts;
    const std::size_t have = static_cast<std::size_t>(list.size());
    if (have + need <= static_cast<std::size_t>(list.capacity())) continue;
    const auto last = std::lower_bound(last_need.begin(), last_need.end(), std::make_pair(id, std::size_t{0}));
    const std::size_t before = last != last_need.end() && last->first == id ? last->second : 0;
    const std::size_t growth = need > before ? need - before : 0;
    const std::size_t want =
        std::min<std::size_t>(have + need + need / 8 + 2 * growth, std::numeric_limits<int>::max());
    if (have == 0) list.clear();  // frees the block: nothing in it to copy
    list.reserve(static_cast<int>(want));
  }
  last_need.swap(need_now);
}

}  // namespace

double runawayContacts(const btSoftBody& a, const btSoftBody& b) {
  const auto meanRestArea = [](const btSoftBody& body) {
    double area = 0.0;
    for (int f = 0; f < body.m_faces.size(); ++f) area += double(body.m_faces[f].m_ra);
    return body.m_faces.size() > 0 ? area / body.m_faces.size() : 0.0;
  };
  const double margins = double(a.getCollisionShape()->getMargin()) + double(b.getCollisionShape()->getMargin());
  const double finest = std::min(meanRestArea(a), meanRestArea(b));
  const double kPi = 3.14159265358979323846;
  const double per_node = finest > 0.0 ? std::max(1.0, kPi * margins * margins / finest) : 1.0;
  return double(kRunawayContactsPerNode) * per_node * double(std::min(a.m_nodes.size(), b.m_nodes.size()));
}

bool isRunaway(const btSoftBody& a, const btSoftBody& b, std::size_t contacts) {
  const auto nodes = static_cast<std::size_t>(std::min(a.m_nodes.size(), b.m_nodes.size()));
  return contacts > kRunawayContactsPerNode * nodes && double(contacts) > runawayContacts(a, b);
}

Installation::Installation(btSoftRigidDynamicsWorld& world, const Settings& settings)
    : world_(world), dispatcher_(collisionDispatcherOf(world)), settings_(settings), sensors_(coreSettings(settings)) {
  if (settings.exact != ExactTest::Bullet && settings.exact != ExactTest::Robust &&
      settings.exact != ExactTest::Continuous)
    throw psc::Error(psc::ErrorCode::InvalidSettings,
                     "psc::bullet::Settings::exact = " + std::to_string(static_cast<int>(settings.exact)) +
                         " is not an ExactTest (Bullet, Robust or Continuous)");
  previous_ = detail::DispatcherAccess::contactCreateFunc(dispatcher_, kSoft, kSoft);
  if (dynamic_cast<const detail::SoftSoftCreateFunc*>(previous_) != nullptr)
    throw psc::Error(psc::ErrorCode::InvalidArgument,
                     "psc::bullet::install: a psc::bullet plugin is already installed on this world's dispatcher");
  dispatcher_.registerCollisionCreateFunc(kSoft, kSoft, &create_func_);
  world_.addAction(&end_of_dispatch_);
  // A plugin installed earlier on this world may have marked the current step as sensed.
  world_.getDispatchInfo().m_stepCount = 0;
  refreshSoftBodyPairs();
}

Installation::~Installation() {
  if (solver_ != nullptr) detach(*solver_);
  // Give back the previous algorithm only if nobody registered over ours meanwhile.
  if (detail::DispatcherAccess::contactCreateFunc(dispatcher_, kSoft, kSoft) == &create_func_)
    dispatcher_.registerCollisionCreateFunc(kSoft, kSoft, previous_);
  world_.removeAction(&end_of_dispatch_);
  refreshSoftBodyPairs();
  // Every algorithm of ours sat in a soft-soft pair of this world's pair cache; one that survived
  // would call into freed memory at the next dispatch.
  assert(live_algorithms_.load() == 0);
}

void Installation::refreshSoftBodyPairs() {
  btOverlappingPairCache* cache = world_.getBroadphase()->getOverlappingPairCache();
  btBroadphasePairArray& pairs = cache->getOverlappingPairArray();
  for (int i = 0; i < pairs.size(); ++i) {
    btBroadphasePair& pair = pairs[i];
    if (pair.m_algorithm == nullptr || pair.m_pProxy0 == nullptr || pair.m_pProxy1 == nullptr) continue;
    const auto* object0 = static_cast<const btCollisionObject*>(pair.m_pProxy0->m_clientObject);
    const auto* object1 = static_cast<const btCollisionObject*>(pair.m_pProxy1->m_clientObject);
    // Only soft-soft pairs: soft-rigid pairs keep their algorithms (and anything they cache).
    if (btSoftBody::upcast(object0) != nullptr && btSoftBody::upcast(object1) != nullptr)
      cache->cleanOverlappingPair(pair, &dispatcher_);
  }
}

void EndOfDispatch::updateAction(btCollisionWorld*, btScalar) { owner_.endOfDispatch(); }

bool Installation::collide(btSoftBody& a, btSoftBody& b) noexcept {
  std::lock_guard<std::mutex> lock(mutex_);
  try {
    senseOncePerStep();
    if (!step_ok_) return false;
    // Only bodies the sensor world still sees as they are: a dispatch between steps (a manual
    // performDiscreteCollisionDetection, contactTest) after a body's arrays changed must not use
    // this step's candidates for it (a review's finding, stop 46). Bullet's algorithm takes it.
    const std::optional<psc::BodyId> id_a = registry_.currentIdOf(a);
    const std::optional<psc::BodyId> id_b = registry_.currentIdOf(b);
    if (!id_a || !id_b || *id_a == *id_b) return false;
    collidePair(a, *id_a, b, *id_b);
    return true;
  } catch (const std::exception& error) {
    stats_.error = error.what();
  } catch (...) {
    stats_.error = "unknown exception in psc::bullet's soft-soft collision";
  }
  return false;
}

void Installation::collidePair(btSoftBody& a, psc::BodyId id_a, btSoftBody& b, psc::BodyId id_b) {
  const std::uint64_t key = (std::uint64_t{std::min(id_a, id_b)} << 32) | std::max(id_a, id_b);
  // A second dispatch in the same step (e.g. a manual performDiscreteCollisionDetection) would
  // push every contact again: each (node, face) is tested at most once a step.
  if (!collided_pairs_.insert(key).second) return;
  const auto start = std::chrono::steady_clock::now();
  const std::vector<psc::CandidatePair>& candidates = sensors_.lastResult().candidates;
  const int before_a = a.m_scontacts.size(), before_b = b.m_scontacts.size();
  const auto ab = candidatesOf(candidates, id_a, id_b);
  const ExactCounts ab_counts = collideCandidates(settings_.exact, a, b, ab.first, ab.second, settings_.contacts);
  const auto ba = candidatesOf(candidates, id_b, id_a);
  const ExactCounts ba_counts = collideCandidates(settings_.exact, b, a, ba.first, ba.second, settings_.contacts);
  addCounts(ab_counts);
  addCounts(ba_counts);
  // The rule counts what the exact test accepted, before ContactSet::NearestFace kept the nearest.
  const std::size_t contacts = ab_counts.contacts + ab_counts.reduced + ba_counts.contacts + ba_counts.reduced;
  const bool runaway = isRunaway(a, b, contacts);
  // Every exact test (Continuous's crossing contacts, made at the margins, are never in the band).
  const btScalar radius = a.getCollisionShape()->getMargin() + b.getCollisionShape()->getMargin();
  // From the step the pair runs away (that step's contacts included) until it has none.
  if (settings_.runaway_sharing && runaway) sharing_pairs_.insert(key);
  if (contacts == 0) {
    sharing_pairs_.erase(key);
  } else if (sharing_pairs_.count(key) != 0) {
    stats_.shared_contacts += shareBandWeights(a, before_a, radius) + shareBandWeights(b, before_b, radius);
    ++stats_.sharing_pairs;
  } else if (settings_.crowded_band > 0) {
    const std::size_t crowded = shareBandWeights(a, before_a, radius, settings_.crowded_band) +
                                shareBandWeights(b, before_b, radius, settings_.crowded_band);
    stats_.shared_contacts += crowded;
    stats_.crowded_contacts += crowded;
  }
  if (runaway && settings_.runaway_fallback && settings_.exact != ExactTest::Continuous &&
      settings_.sensors.motion_bound == psc::MotionBound::Radius && !sensors_.pairAhead(id_a, id_b)) {
    sensors_.setPairAhead(id_a, id_b, true);
    ++stats_.runaway_fallbacks;
  }
  if (runaway && ++stats_.runaway_pairs == 1) {
    const btSoftBody::tSoftBodyArray& all = world_.getSoftBodyArray();
    stats_.runaway = "psc::bullet: runaway contact between soft bodies " + std::to_string(all.findLinearSearch(&a)) +
                     " and " + std::to_string(all.findLinearSearch(&b)) + " of the world: " +
                     std::to_string(contacts) + " contacts in one step, over " +
                     std::to_string(static_cast<std::size_t>(runawayContacts(a, b))) +
                     "; they are inside each other or faster than the contact radius follows";
  }
  ++stats_.body_pairs;
  stats_.ms_exact += millisecondsSince(start);
}

void Installation::endOfDispatch() noexcept {
  std::lock_guard<std::mutex> lock(mutex_);
  try {
    senseOncePerStep();
    if (step_ok_ && settings_.beyond_broadphase) collideUndispatchedPairs();
    if (step_ok_) collideSelfPairs();
  } catch (const std::exception& error) {
    stats_.error = error.what();
  } catch (...) {
    stats_.error = "unknown exception in psc::bullet's soft-soft collision";
  }
}

void Installation::afterPredictMotion(const btSoftBody& body) noexcept {
  std::lock_guard<std::mutex> lock(mutex_);
  // Only a body the next sync will leave as it is: a new, changed or re-meshed one is refit by the
  // sensor step after the sync. The step is the one that tells the user about a failure.
  // (Bullet resets m_stepCount only after predictMotion, so sensedThisStep() cannot tell here
  // whether this step's sensors have run: the call's place is the caller's contract.)
  if (!participates(body)) return;
  const std::optional<psc::BodyId> id = registry_.currentIdOf(body);
  if (!id) return;
  const auto start = std::chrono::steady_clock::now();
  try {
    if (sensors_.refitNow(*id)) ++ahead_bodies_;
  } catch (...) {
    // A non-finite node: the sensor step refits the body again and reports it (Stats::error).
  }
  ahead_ms_ += millisecondsSince(start);
}

void Installation::attach(SoftBodySolver& solver) {
  if (solver.installation_ == this) return;
  if (solver.installation_ != nullptr) solver.installation_->detach(solver);
  if (solver_ != nullptr) detach(*solver_);
  solver.installation_ = this;
  solver_ = &solver;
}

void Installation::detach(SoftBodySolver& solver) {
  if (solver.installation_ == this) solver.installation_ = nullptr;
  if (solver_ == &solver) solver_ = nullptr;
}

void Installation::collideUndispatchedPairs() {
  // The walk over the candidates is part of the exact stage's time (a review's finding, stop 46:
  // about 0.6 ns a candidate went untimed): the pairs collided here add their own time, which the
  // walk's includes, so the walk's replaces theirs.
  const auto start = std::chrono::steady_clock::now();
  const double ms_exact_before = stats_.ms_exact;
  const std::vector<psc::CandidatePair>& candidates = sensors_.lastResult().candidates;
  btOverlappingPairCache* cache = world_.getBroadphase()->getOverlappingPairCache();
  for (std::size_t i = 0; i < candidates.size();) {
    const psc::BodyId vb = candidates[i].vertex_body;
    const psc::BodyId tb = candidates[i].triangle_body;
    while (i < candidates.size() && candidates[i].vertex_body == vb && candidates[i].triangle_body == tb) ++i;
    if (vb == tb) continue;  // self-collision: collideSelfPairs
    const std::uint64_t key = (std::uint64_t{std::min(vb, tb)} << 32) | std::max(vb, tb);
    if (collided_pairs_.count(key) != 0) continue;
    btSoftBody* a = registry_.bodyOf(vb);
    btSoftBody* b = registry_.bodyOf(tb);
    if (a == nullptr || b == nullptr || a->getBroadphaseHandle() == nullptr || b->getBroadphaseHandle() == nullptr ||
        registry_.currentIdOf(*a) != vb || registry_.currentIdOf(*b) != tb)
      continue;
    if (!cache->needsBroadphaseCollision(a->getBroadphaseHandle(), b->getBroadphaseHandle()) ||
        !dispatcher_.needsCollision(a, b))
      continue;
    // A pair the broadphase has was offered to the dispatcher this step: not collided, it was
    // refused (the program's near callback, say), and stays refused.
    if (cache->findPair(a->getBroadphaseHandle(), b->getBroadphaseHandle()) != nullptr) continue;
    collidePair(*a, vb, *b, tb);
    ++stats_.beyond_broadphase_pairs;
  }
  stats_.ms_exact = ms_exact_before + millisecondsSince(start);
}

void Installation::addCounts(const ExactCounts& counts) {
  stats_.exact_tests += counts.tests;
  stats_.contacts += counts.contacts;
  stats_.robust_contacts += counts.robust;
  stats_.crossing_contacts += counts.crossings;
  stats_.reduced_contacts += counts.reduced;
}

void Installation::syncSelfCollision() {
  for (psc::BodyId id : sensors_.bodyIds()) {
    const btSoftBody* body = registry_.bodyOf(id);
    if (body == nullptr) continue;
    const auto it = self_overrides_.find(body);
    const bool on = it != self_overrides_.end() ? it->second : settings_.self_collision;
    if (on != sensors_.selfCollision(id)) sensors_.setSelfCollision(id, on);
  }
}

void Installation::collideSelfPairs() {
  const std::vector<psc::CandidatePair>& candidates = sensors_.lastResult().candidates;
  for (psc::BodyId id : sensors_.bodyIds()) {
    if (!sensors_.selfCollision(id)) continue;
    btSoftBody* body = registry_.bodyOf(id);
    const auto range = candidatesOf(candidates, id, id);
    if (body == nullptr || range.first == range.second || registry_.currentIdOf(*body) != id) continue;
    const auto start = std::chrono::steady_clock::now();
    const auto radius = static_cast<btScalar>(sensors_.selfRadius(id));
    const int before = body->m_scontacts.size();
    const ExactCounts counts =
        collideCandidates(settings_.exact, *body, *body, radius, range.first, range.second, settings_.contacts);
    // Bullet's test accepts at the margins + 2·|m_x − m_q| and makes that the contact's margin, the
    // distance the solver pushes the node out to: a body moving fast as a whole would push its own
    // layers apart by its speed. A self contact's margin is the self rule's radius instead,
    // selfRadius + motion_factor × selfMotion (the node's motion against its body's), within which
    // the core took the pair. (Continuous has no motion term: its margins are the radius already.)
    const psc::Vec3 mean = sensors_.selfMeanMotion(id);
    const double factor = sensors_.settings().motion_factor;
    for (int i = before; i < body->m_scontacts.size(); ++i) {
      btSoftBody::SContact& c = body->m_scontacts[i];
      const btVector3 d = c.m_node->m_x - c.m_node->m_q;
      const psc::Vec3 dv(double(d.x()), double(d.y()), double(d.z()));
      const double rule = double(radius) + factor * psc::selfMotion(dv, mean);
      if (double(c.m_margin) > rule) c.m_margin = static_cast<btScalar>(rule);
    }
    addCounts(counts);
    stats_.self_exact_tests += counts.tests;
    stats_.self_contacts += counts.contacts;
    ++stats_.self_bodies;
    stats_.ms_exact += millisecondsSince(start);
  }
}

void Installation::setSelfCollision(const btSoftBody* body, bool on) {
  if (body == nullptr) return;
  std::lock_guard<std::mutex> lock(mutex_);
  self_overrides_[body] = on;
}

void Installation::collideFallback(btCollisionAlgorithm& fallback, const btCollisionObjectWrapper* body0,
                                   const btCollisionObjectWrapper* body1, const btDispatcherInfo& info,
                                   btManifoldResult* result) {
  std::lock_guard<std::mutex> lock(mutex_);
  ++stats_.fallback_pairs;
  fallback.processCollision(body0, body1, info, result);
}

bool Installation::sensedThisStep() const { return world_.getDispatchInfo().m_stepCount == kSensed; }

void Installation::senseOncePerStep() {
  // Lazily, at the first soft-soft pair of a step (or at the end of its dispatch when there was
  // none): predictMotion has run for every soft body by then (m_x predicted, m_q previous).
  if (sensedThisStep()) return;
  world_.getDispatchInfo().m_stepCount = kSensed;
  // A sharing pair that was not collided last step has parted (no candidates, no dispatch).
  for (auto it = sharing_pairs_.begin(); it != sharing_pairs_.end();)
    it = collided_pairs_.count(*it) != 0 ? std::next(it) : sharing_pairs_.erase(it);
  collided_pairs_.clear();
  const std::uint64_t sensor_steps = stats_.sensor_steps + 1;
  stats_ = Stats{};
  stats_.sensor_steps = sensor_steps;
  stats_.refit_after_predict = ahead_bodies_;
  const double ahead_ms = ahead_ms_;
  ahead_bodies_ = 0;
  ahead_ms_ = 0.0;
  step_ok_ = false;
  const auto start = std::chrono::steady_clock::now();
  try {
    detail::SyncCounters sync;
    std::vector<const btSoftBody*> left;
    registry_.sync(
        world_.getSoftBodyArray(), [this](const btSoftBody& body) { return participates(body); }, sensors_, sync,
        left);
    for (const btSoftBody* body : left) overrides_.erase(body), self_overrides_.erase(body);
    syncSelfCollision();
    stats_.bodies = sync.bodies;
    stats_.skipped_bodies = sync.skipped;
    stats_.skipped_reason = sync.first_rejection;
    // A body whose input the core cannot step (its nodes became non-finite) is left out, like a
    // body rejected when it came (stats: skipped_bodies, skipped_reason), and the others are stepped:
    // one broken body must not take the sensors away from every pair.
    const psc::StepResult* stepped = nullptr;
    for (std::size_t tries = 0; stepped == nullptr; ++tries) {
      try {
        stepped = &sensors_.step();
      } catch (const psc::Error& error) {
        if (error.body() == psc::Error::kNoBody || tries > sync.bodies ||
            !registry_.reject(error.body(), error.what(), sensors_, sync))
          throw;
        stats_.bodies = sync.bodies;
        stats_.skipped_bodies = sync.skipped;
        stats_.skipped_reason = sync.first_rejection;
      }
    }
    const psc::StepResult& result = *stepped;
    stats_.core = result.stats;
    stats_.particles = result.stats.particles;
    stats_.rounds = result.stats.rounds;
    stats_.round_cap_hits = result.stats.round_cap_hits;
    stats_.flagged_pairs = result.stats.flagged_pairs;
    stats_.candidate_pairs = result.candidates.size();
    reserveContacts(result.candidates, registry_, contact_need_);
    stats_.repartitions = result.stats.repartitions;
    step_ok_ = true;
  } catch (const std::exception& error) {
    stats_.error = error.what();
  }
  stats_.ms_sensor_step = millisecondsSince(start) + ahead_ms;
}

void Installation::setEnabled(const btSoftBody* body, std::optional<bool> enabled) {
  if (body == nullptr) return;
  if (enabled) {
    overrides_[body] = *enabled;
  } else {
    overrides_.erase(body);
  }
}

bool Installation::participates(const btSoftBody& body) const {
  const auto it = overrides_.find(&body);
  if (it != overrides_.end()) return it->second;
  return settings_.opt_in == OptIn::VfSsFlag && (body.m_cfg.collisions & btSoftBody::fCollision::VF_SS) != 0;
}

void Installation::refreshBody(const btSoftBody* body) {
  if (body != nullptr) registry_.markDirty(body);
}

std::optional<psc::BodyId> Installation::bodyId(const btSoftBody* body) const { return registry_.idOf(body); }

bool Installation::owns(const btCollisionAlgorithm* algorithm) const {
  const auto* ours = dynamic_cast<const detail::SoftSoftAlgorithm*>(algorithm);
  return ours != nullptr && &ours->owner() == this;
}

}  // namespace psc::bullet
