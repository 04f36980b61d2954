// One call puts psc's particle sensors in charge of a btSoftRigidDynamicsWorld's soft-soft
// collisions:
//
//   auto plugin = psc::bullet::install(world);   // before or after bodies were added
//   world.stepSimulation(dt);                    // unchanged
//
// What install() does, and what it leaves alone:
// - registers a btCollisionAlgorithm for (SOFTBODY, SOFTBODY) on the world's btCollisionDispatcher
//   and refreshes the broadphase pairs that had cached Bullet's algorithm;
// - steps the sensor world once per simulation (sub)step, at the first soft-soft pair Bullet
//   dispatches in that step, or at the end of the dispatch when there was none: always after
//   btSoftBody::predictMotion, so m_x are the predicted node positions and m_q the previous ones.
//   A new step is recognised by btDispatcherInfo::m_stepCount, which the world resets to 0 before
//   each dispatch and nothing else in Bullet 3.24 uses: the plugin writes its own mark there;
// - adds a btActionInterface to the world (the end of each step's dispatch), where it collides
//   the candidate pairs the broadphase did not dispatch (Settings::beyond_broadphase);
// - for each pair of participating bodies runs Bullet's own btSoftColliders::CollideVF_SS on the
//   core's candidate (node, face) pairs, both directions, each at most once per step, so the
//   btSoftBody::SContacts are the ones Bullet's default path makes for the same (node, face)
//   (then, by default, the constraint mixing of crowded nodes and runaway pairs shared:
//   Settings::crowded_band, runaway_sharing; a self contact's margin is the self rule's radius);
// - soft-rigid and rigid-rigid collision are untouched; pairs with a non-participating body go to
//   the algorithm registered before install() (Bullet's own by default);
// - self-collision only where asked (Settings::self_collision, setSelfCollision): the core's
//   self candidates of the body through the same exact test, at the end of the dispatch.
//
// Lifetime: the Plugin must be destroyed (or uninstall()ed) before the world, its dispatcher and
// its broadphase, like any object one adds to a world. Destruction restores the previous algorithm.
#pragma once

#include "psc/bullet/precision.h"
#include "psc/bullet/settings.h"
#include "psc/bullet/stats.h"
#include "psc/world.h"

#include <memory>
#include <optional>

class btSoftRigidDynamicsWorld;
class btSoftBody;
class btCollisionAlgorithm;

namespace psc::bullet {

class Installation;
class SoftBodySolver;

/// Owns everything install() added to a world. Move-only; empty after a move or uninstall().
class Plugin {
 public:
  Plugin();  ///< empty; defined where Installation is complete
  explicit Plugin(std::unique_ptr<Installation> installation);
  ~Plugin();  ///< uninstalls
  Plugin(Plugin&&) noexcept;
  Plugin& operator=(Plugin&&) noexcept;  ///< uninstalls what this held before
  Plugin(const Plugin&) = delete;
  Plugin& operator=(const Plugin&) = delete;

  /// Restores the (SOFTBODY, SOFTBODY) algorithm that was registered before install() and drops
  /// every algorithm of the plugin from the world's pair cache. Idempotent.
  void uninstall();
  bool installed() const { return impl_ != nullptr; }

  /// Per-body choice that overrides Settings::opt_in. Keyed by the body's address; kept while the
  /// body is in the world (it may be set before addSoftBody) and forgotten once the plugin sees the
  /// body gone from the world, so set it again after re-adding a body.
  void setEnabled(const btSoftBody* body, bool enabled);
  /// Back to the rule of Settings::opt_in for this body.
  void clearEnabled(const btSoftBody* body);
  /// Self-collision of one body (overrides Settings::self_collision); kept like setEnabled. The
  /// body's node positions when the sensors first see it with self-collision on are its rest shape:
  /// node-face pairs that close there are never self contacts (psc::SensorWorld::setSelfCollision).
  void setSelfCollision(const btSoftBody* body, bool on);
  /// Whether the body participates under the current rule and overrides (whatever its world).
  bool participates(const btSoftBody* body) const;
  /// The body's triangles changed in place (same counts, same buffers): re-read them next step.
  /// Changes of node or face counts, and reallocation of m_nodes / m_faces, are detected alone.
  void refreshBody(const btSoftBody* body);

  /// Optional, for speed: call right after `body`'s btSoftBody::predictMotion (what
  /// psc::bullet::SoftBodySolver does for every body). The sensors then refit the body's boxes at
  /// once, while its nodes are still in the cache, instead of reading all of them again, cold, at
  /// the step's first soft-soft pair (the refit is the one stage that reads every node: 5.4 against
  /// 6.3 ms a step on 8 bodies of 50,000 nodes). Nothing else changes: same candidates, same
  /// contacts. The nodes' m_x and m_q must not change between this call and the step's collision
  /// dispatch (in Bullet's own step nothing moves them there); a call at another time leaves the
  /// sensors with stale boxes. Ignored for a body the plugin does not hold yet or that changed
  /// since the last step (the sensor step refits those). Never throws.
  void afterPredictMotion(const btSoftBody& body);
  /// Makes `solver` (the world's soft-body solver) call afterPredictMotion for every body it moves,
  /// until the plugin is uninstalled or the solver destroyed; a solver serves one plugin at a time
  /// (attaching moves it). See psc/bullet/solver.h.
  void attach(SoftBodySolver& solver);

  /// Counters of the most recent step (see Stats).
  const Stats& stats() const;
  /// The sensor world behind the plugin, for inspection (particles, partitions, μ).
  const psc::SensorWorld& sensorWorld() const;
  /// The body's id in sensorWorld(), or nothing when it is not handled by the sensors (yet).
  std::optional<psc::BodyId> bodyId(const btSoftBody* body) const;
  /// Whether `algorithm` (e.g. a broadphase pair's m_algorithm) is one of the plugin's.
  bool owns(const btCollisionAlgorithm* algorithm) const;

 private:
  std::unique_ptr<Installation> impl_;
};

/// Installs the plugin on `world`. Throws psc::Error(InvalidArgument) when the world's dispatcher
/// is not a btCollisionDispatcher or a plugin is already installed on it, and
/// psc::Error(InvalidSettings) for settings out of range. The third argument is the link-time
/// precision guard: leave it defaulted.
Plugin install(btSoftRigidDynamicsWorld& world, const Settings& settings = {},
               PrecisionTag<btScalar> = {});

}  // namespace psc::bullet
