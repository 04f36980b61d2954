// Private: everything one install() put into a world, and the per-step flow of the plugin.
#pragma once

#include "body_registry.h"
#include "soft_soft_algorithm.h"
#include "psc/bullet/exact.h"
#include "psc/bullet/settings.h"
#include "psc/bullet/stats.h"
#include "psc/world.h"

#include <BulletDynamics/Dynamics/btActionInterface.h>

#include <atomic>
#include <cstdint>
#include <mutex>
#include <optional>
#include <unordered_map>
#include <unordered_set>
#include <utility>
#include <vector>

class btSoftRigidDynamicsWorld;
class btCollisionDispatcher;

namespace psc::bullet {

class Installation;
class SoftBodySolver;

/// The end of each simulation step's collision dispatch. Bullet calls actions in updateActions(),
/// on every internal (sub)step, after the dispatch and before the soft bodies are solved
/// (btSoftRigidDynamicsWorld solves them after btDiscreteDynamicsWorld's step returns), so node
/// positions are still those of the dispatch and soft contacts added here are still solved.
class EndOfDispatch final : public btActionInterface {
 public:
  explicit EndOfDispatch(Installation& owner) : owner_(owner) {}
  void updateAction(btCollisionWorld*, btScalar) override;
  void debugDraw(btIDebugDraw*) override {}

 private:
  Installation& owner_;
};

class Installation {
 public:
  Installation(btSoftRigidDynamicsWorld& world, const Settings& settings);
  ~Installation();  ///< uninstalls
  Installation(const Installation&) = delete;
  Installation& operator=(const Installation&) = delete;

  // --- called by the algorithm, inside Bullet's dispatch ---
  /// Collides the pair from the sensors' candidates; false when the pair is not the sensors'
  /// (then the caller hands it to the previous algorithm). Never throws.
  bool collide(btSoftBody& a, btSoftBody& b) noexcept;
  /// Runs Bullet's previous algorithm on a soft-soft pair that is not the sensors', under the
  /// plugin's lock: Bullet's own test pushes into both bodies' m_scontacts, which the plugin's
  /// pairs (and the room it reserves in them each step) write too, so under a dispatcher that
  /// collides pairs on several threads the two must not overlap.
  void collideFallback(btCollisionAlgorithm& fallback, const btCollisionObjectWrapper* body0,
                       const btCollisionObjectWrapper* body1, const btDispatcherInfo& info, btManifoldResult* result);
  btCollisionAlgorithmCreateFunc* previousCreateFunc() const { return previous_; }
  void algorithmCreated() { ++live_algorithms_; }
  void algorithmDestroyed() { --live_algorithms_; }
  /// Called by EndOfDispatch after the dispatch: steps the sensors if no soft-soft pair did, and
  /// (Settings::beyond_broadphase) collides the candidate pairs the broadphase did not dispatch.
  void endOfDispatch() noexcept;
  /// Plugin::afterPredictMotion: the body's refit now, while its nodes are in the cache. Never throws.
  void afterPredictMotion(const btSoftBody& body) noexcept;
  /// Plugin::attach; detach is also called by the solver's destructor.
  void attach(SoftBodySolver& solver);
  void detach(SoftBodySolver& solver);

  // --- Plugin's API ---
  void setEnabled(const btSoftBody* body, std::optional<bool> enabled);
  void setSelfCollision(const btSoftBody* body, bool on);
  bool participates(const btSoftBody& body) const;
  void refreshBody(const btSoftBody* body);
  const Stats& stats() const { return stats_; }
  const psc::SensorWorld& sensorWorld() const { return sensors_; }
  std::optional<psc::BodyId> bodyId(const btSoftBody* body) const;
  bool owns(const btCollisionAlgorithm* algorithm) const;

 private:
  /// Steps the sensors when Bullet has started a new simulation step since the last sensor step.
  void senseOncePerStep();
  bool sensedThisStep() const;
  /// Drops the cached algorithm of every soft-soft pair, so the dispatcher asks its create funcs
  /// again (a pair keeps the algorithm it got first, even after a new registration).
  void refreshSoftBodyPairs();
  /// Both directions of one body pair from the step's candidates, once per step.
  void collidePair(btSoftBody& a, psc::BodyId id_a, btSoftBody& b, psc::BodyId id_b);
  /// Participating body pairs with candidates that Bullet's broadphase did not dispatch, filtered
  /// the way Bullet filters dispatched pairs (broadphase groups/masks and overlap filter callback,
  /// dispatcher's needsCollision).
  void collideUndispatchedPairs();
  /// Adds one exact-stage call's counts to the step's Stats.
  void addCounts(const ExactCounts& counts);
  /// Switches the core's self-collision of each body to what the settings and overrides say.
  void syncSelfCollision();
  /// Each self-colliding body against itself, from the step's candidates.
  void collideSelfPairs();

  btSoftRigidDynamicsWorld& world_;
  btCollisionDispatcher& dispatcher_;
  Settings settings_;
  btCollisionAlgorithmCreateFunc* previous_ = nullptr;
  detail::SoftSoftCreateFunc create_func_{*this};
  EndOfDispatch end_of_dispatch_{*this};
  psc::SensorWorld sensors_;
  detail::BodyRegistry registry_;
  std::unordered_map<const btSoftBody*, bool> overrides_;
  std::unordered_map<const btSoftBody*, bool> self_overrides_;

  mutable std::mutex mutex_;  ///< Bullet may dispatch pairs from several threads (btCollisionDispatcherMt)
  bool step_ok_ = false;
  std::unordered_set<std::uint64_t> collided_pairs_;  ///< body-id pairs collided in this step
  /// Settings::runaway_sharing: body-id pairs that ran away and have not had a step without contact.
  std::unordered_set<std::uint64_t> sharing_pairs_;
  /// Each body's candidates of the last step (by body id, ascending): how fast its contact array
  /// grows (reserveContacts).
  std::vector<std::pair<psc::BodyId, std::size_t>> contact_need_;
  Stats stats_;
  SoftBodySolver* solver_ = nullptr;  ///< attached (Plugin::attach)
  double ahead_ms_ = 0.0;            ///< afterPredictMotion's time since the last sensor step
  std::size_t ahead_bodies_ = 0;     ///< bodies it refit since then
  std::atomic<long> live_algorithms_{0};
};

}  // namespace psc::bullet
