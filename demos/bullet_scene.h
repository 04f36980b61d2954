// A Scene as an ordinary Bullet 3.24 soft-body world, plus the two instruments the benchmark needs
// inside Bullet's step:
//  - SceneDynamicsWorld: hooks right before and after collision detection, where Bullet's
//    positions are the ones contacts are decided on (m_x predicted, m_q previous) and
//    m_scontacts holds this step's soft-soft contacts.
//  - TimedSoftBodySolver: Bullet's default solver, with the face-tree refit (done in
//    btSoftBody::predictMotion only when VF_SS built a face tree) split off and timed, because it
//    exists only for soft-soft collision while the node-tree refit beside it is paid by every
//    pipeline; and the world's self-collision pass (between the soft solve and updateSoftBodies)
//    timed, where Bullet's cluster self-collision happens.
#pragma once

#include "scenes.h"

#include <BulletSoftBody/btDefaultSoftBodySolver.h>
#include <BulletSoftBody/btSoftBody.h>
#include <BulletSoftBody/btSoftBodyRigidBodyCollisionConfiguration.h>
#include <BulletSoftBody/btSoftRigidDynamicsWorld.h>
#include <btBulletDynamicsCommon.h>

#include <chrono>
#include <functional>
#include <memory>
#include <vector>

namespace psc::demo {

class SceneDynamicsWorld : public btSoftRigidDynamicsWorld {
 public:
  using btSoftRigidDynamicsWorld::btSoftRigidDynamicsWorld;
  std::function<void()> before_collision;  ///< right before performDiscreteCollisionDetection
  std::function<void()> after_collision;   ///< right after it, before the constraint solvers
  void performDiscreteCollisionDetection() override;
};

class TimedSoftBodySolver : public btDefaultSoftBodySolver {
 public:
  /// Body by body: the face tree is detached during btSoftBody::predictMotion and refit right
  /// after it with the same code, timed, while the body's nodes are in the cache; then
  /// setAfterPredict's hook. Equivalent to Bullet's order as long as no body uses frame pose
  /// matching (kMT with setPose(…, true)), which moves nodes between the two refits; bodies that
  /// do are left to Bullet and their face refit is not split off (counted in faceRefitSkipped()).
  void predictMotion(btScalar dt) override;
  /// Called right after each body's predictMotion (and its face refit): the sensor pipeline's
  /// psc::bullet::Plugin::afterPredictMotion, as psc::bullet::SoftBodySolver does it.
  void setAfterPredict(std::function<void(const btSoftBody&)> hook) { after_predict_ = std::move(hook); }
  /// false: plain btDefaultSoftBodySolver behaviour (for the test that the split changes nothing).
  void setSplit(bool split) { split_ = split; }
  double lastFaceRefitMs() const { return face_refit_ms_; }
  double lastPredictMs() const { return predict_ms_; }   ///< everything else in predictMotion
  std::size_t faceRefitSkipped() const { return skipped_; }

  /// btSoftRigidDynamicsWorld runs its self-collision pass (psb->defaultCollisionHandler(psb) for
  /// every body) between solveConstraints and updateSoftBodies: the two overrides time it.
  void solveConstraints(btScalar dt) override;
  /// With setCallClusterSelf(true), first Bullet's own cluster self-collision for every body that
  /// has clusters: btSoftColliders::CollideCL_SS::ProcessSoftSoft(psb, psb), the call the CL_SS
  /// case of defaultCollisionHandler(psb) makes for CL_SELF and which Bullet 3.24 never reaches
  /// (docs/BULLET.md, "Self-collision"). Its contacts are cluster joints, solved next step.
  void updateSoftBodies() override;
  void setCallClusterSelf(bool on) { call_cluster_self_ = on; }
  double lastSelfPassMs() const { return self_pass_ms_; }                    ///< the world's self pass (+ the call)
  std::size_t lastSelfClusterContacts() const { return self_cluster_contacts_; }  ///< joints it made

 private:
  std::function<void(const btSoftBody&)> after_predict_;
  double face_refit_ms_ = 0.0;
  double predict_ms_ = 0.0;
  std::size_t skipped_ = 0;
  bool split_ = true;
  bool call_cluster_self_ = false;
  std::chrono::steady_clock::time_point self_pass_start_;
  std::size_t joints_before_self_ = 0;
  double self_pass_ms_ = 0.0;
  std::size_t self_cluster_contacts_ = 0;
};

/// Joints of the bodies: Bullet's cluster contacts are joints (psc_demo makes no other joint).
std::size_t jointCount(const std::vector<btSoftBody*>& bodies);

struct WorldOptions {
  /// btSoftBody::m_cfg.collisions of every soft body. Bullet's own soft-soft pipeline needs VF_SS
  /// (Bullet's default, SDF_RS alone, has no soft-soft collision at all).
  int soft_collision_flags = btSoftBody::fCollision::SDF_RS | btSoftBody::fCollision::VF_SS;
  /// Build the VF_SS trees with initializeVFTrees() (same trees, O(F log F)) instead of leaving
  /// it to Bullet's first predictMotion (O(F²), and a hang on bodies in several pieces).
  bool fast_vf_setup = true;
  /// Time the face-tree refit separately (TimedSoftBodySolver); false = Bullet's solver as is.
  bool split_face_refit = true;
  /// > 0: btSoftBody::generateClusters(clusters) on every soft body before it joins the world
  /// (Bullet's cluster collision; soft_collision_flags then say CL_SS, CL_SELF).
  int clusters = 0;
  /// TimedSoftBodySolver::setCallClusterSelf: Bullet's cluster self-collision called directly.
  bool call_cluster_self = false;
  /// Runs after the world exists and before any body is added (e.g. installs a midphase).
  std::function<void(SceneDynamicsWorld&)> before_bodies;
};

/// Owns a Bullet world built from a Scene. Soft body i is scene.bodies[i], with the same vertex
/// and triangle order (node i = vertex i, face t = triangle t).
class SceneWorld {
 public:
  SceneWorld(const Scene& scene, const WorldOptions& options = {});
  ~SceneWorld();
  SceneWorld(const SceneWorld&) = delete;
  SceneWorld& operator=(const SceneWorld&) = delete;

  /// One fixed step of scene.dt (stepSimulation(dt, 0): exactly one internal step).
  void step();

  SceneDynamicsWorld& world() { return *world_; }
  TimedSoftBodySolver& softSolver() { return *soft_solver_; }
  btSoftBodyWorldInfo& worldInfo() { return world_info_; }
  const std::vector<btSoftBody*>& softBodies() const { return soft_; }
  const Scene& scene() const { return scene_; }

  /// Body index of the soft body that owns this face (pointer into its m_faces); -1 if none.
  int faceOwner(const btSoftBody::Face* face) const;

  /// Kept alive until the world goes and destroyed before it (e.g. a midphase install handle).
  void attach(std::shared_ptr<void> thing) { attachments_.push_back(std::move(thing)); }

 private:
  const Scene& scene_;
  btSoftBodyWorldInfo world_info_;
  std::unique_ptr<btSoftBodyRigidBodyCollisionConfiguration> config_;
  std::unique_ptr<btCollisionDispatcher> dispatcher_;
  std::unique_ptr<btDbvtBroadphase> broadphase_;
  std::unique_ptr<btSequentialImpulseConstraintSolver> solver_;
  std::unique_ptr<TimedSoftBodySolver> soft_solver_;
  std::unique_ptr<SceneDynamicsWorld> world_;
  std::vector<btSoftBody*> soft_;
  std::vector<std::pair<const btSoftBody::Face*, const btSoftBody::Face*>> face_ranges_;
  std::vector<std::unique_ptr<btCollisionShape>> shapes_;
  std::vector<std::unique_ptr<btRigidBody>> rigid_;
  std::vector<std::unique_ptr<btMotionState>> motion_states_;
  std::vector<std::shared_ptr<void>> attachments_;
};

/// The soft body created from a spec (not added to any world).
btSoftBody* createSoftBody(btSoftBodyWorldInfo& info, const SoftBodySpec& spec, int collision_flags,
                           int position_iterations, bool fast_vf_setup = true);

}  // namespace psc::demo
