// Reading Bullet's own soft-soft pipeline without changing it.
//  - ZoneTimer: wall time spent in a named BT_PROFILE zone. Debian's Bullet is built without
//    CProfileManager, but the zones still call the functions set with
//    btSetCustom{Enter,Leave}ProfileZoneFunc. The zone "Deformable Collision" wraps
//    btSoftBody::defaultCollisionHandler(btSoftBody*): for VF_SS that is the node-tree vs
//    face-tree traversal plus every CollideVF_SS exact test, both directions.
//  - countVFExactTests: replays that traversal with a counting callback (outside any timed region)
//    to give the number of exact tests Bullet ran.
//  - bulletMidphaseBytes: what the two trees of Bullet's soft-soft path hold.
#pragma once

#include <BulletSoftBody/btSoftRigidDynamicsWorld.h>

#include <cstddef>

namespace psc::demo {

/// Bullet's zone hooks are process-global: one ZoneTimer may exist at a time (psc_demo runs its
/// worlds one after the other); the previous hooks are restored on destruction.
class ZoneTimer {
 public:
  explicit ZoneTimer(const char* zone);
  ~ZoneTimer();
  ZoneTimer(const ZoneTimer&) = delete;
  ZoneTimer& operator=(const ZoneTimer&) = delete;

  /// Only zones entered while armed are timed (e.g. only during collision detection, so the
  /// self-collision pass after the solver, a no-op for VF_SS, is left out).
  void arm(bool on);
  /// Milliseconds and entries accumulated since the last call.
  double takeMs();
  std::size_t takeCount();
};

/// Exact tests (CollideVF_SS::Process calls) Bullet's VF_SS path runs for the current trees: the
/// same collideTT both ways for every soft-soft pair in the broadphase pair cache that the
/// dispatcher would process.
std::size_t countVFExactTests(btSoftRigidDynamicsWorld& world);

/// Bytes of the node tree, the face tree and the cluster tree (only after generateClusters) of one
/// body (nodes × sizeof(btDbvtNode)).
std::size_t bulletMidphaseBytes(const btSoftBody& body);

}  // namespace psc::demo
