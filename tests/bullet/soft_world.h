// A btSoftRigidDynamicsWorld with the bodies it owns, and the small scenes the tests share.
#pragma once

#include "psc/bullet/solver.h"
#include "psc/shapes.h"

#include <BulletCollision/CollisionDispatch/btCollisionDispatcher.h>
#include <BulletCollision/BroadphaseCollision/btDbvtBroadphase.h>
#include <BulletDynamics/ConstraintSolver/btSequentialImpulseConstraintSolver.h>
#include <BulletDynamics/Dynamics/btRigidBody.h>
#include <BulletSoftBody/btSoftBody.h>
#include <BulletSoftBody/btSoftBodyRigidBodyCollisionConfiguration.h>
#include <BulletSoftBody/btSoftRigidDynamicsWorld.h>
#include <LinearMath/btDefaultMotionState.h>

#include <functional>
#include <memory>
#include <vector>

namespace psc_test {

struct SoftParams {
  double margin = 0.02;        ///< collision margin, m
  double mass = 1.0;           ///< kg, spread over the nodes
  double stiffness = 0.9;      ///< linear stiffness of the links (Bullet's kLST, 0..1)
  double shape_matching = 0.2; ///< Bullet's kMT: pull towards the rest shape (0 = off)
  int iterations = 4;          ///< position iterations
  double friction = 0.4;       ///< Bullet's kDF
  double damping = 0.0;        ///< Bullet's kDP (velocity damping, 0..1)
  bool vf_ss = true;           ///< fCollision::VF_SS on (soft-soft collision in Bullet's default path)
};

/// Makes the world's dispatcher (e.g. one that dispatches pairs from several threads).
using DispatcherFactory = std::function<std::unique_ptr<btCollisionDispatcher>(btCollisionConfiguration*)>;

class SoftWorld {
 public:
  /// `make_dispatcher` empty: a plain btCollisionDispatcher. `psc_solver`: the world's soft-body
  /// solver is `soft_solver` (psc::bullet::SoftBodySolver) instead of Bullet's default.
  explicit SoftWorld(double gravity = -10.0, const DispatcherFactory& make_dispatcher = {}, bool psc_solver = false);
  ~SoftWorld();
  SoftWorld(const SoftWorld&) = delete;
  SoftWorld& operator=(const SoftWorld&) = delete;

  btSoftBody* addSoft(const psc::TriMesh& mesh, const SoftParams& params = {}, const btVector3& velocity = {0, 0, 0});
  /// A box; mass 0 makes it static.
  btRigidBody* addBox(const btVector3& half_extents, double mass, const btVector3& position);
  /// Takes the body out of the world and frees it.
  void destroySoft(btSoftBody* body);

  /// One fixed step of dt (no substep accumulation).
  void step(double dt = 1.0 / 60.0) { world.stepSimulation(btScalar(dt), 0, btScalar(dt)); }
  /// Runs `n` steps, calling `after_dispatch` inside each one right after Bullet's collision
  /// dispatch (an internal tick callback): the soft contacts of the step are in m_scontacts and the
  /// node positions are the ones they were found at (the soft solve has not run yet).
  void run(int n, const std::function<void()>& after_dispatch = {}, double dt = 1.0 / 60.0);

  btSoftBodyRigidBodyCollisionConfiguration config;

 private:
  std::unique_ptr<btCollisionDispatcher> own_dispatcher_;  // declared before `dispatcher`, which refers to it

 public:
  btCollisionDispatcher& dispatcher;
  btDbvtBroadphase broadphase;
  btSequentialImpulseConstraintSolver solver;
  psc::bullet::SoftBodySolver soft_solver;  ///< the world's only with `psc_solver`

 private:
  bool psc_solver_;  // declared before `world`, which reads it

 public:
  btSoftRigidDynamicsWorld world{&dispatcher, &broadphase, &solver, &config, psc_solver_ ? &soft_solver : nullptr};

 private:
  static void tick(btDynamicsWorld* world, btScalar);
  std::function<void()> after_dispatch_;
  std::vector<btSoftBody*> soft_;
  std::vector<std::unique_ptr<btCollisionShape>> shapes_;
  std::vector<std::unique_ptr<btDefaultMotionState>> motion_states_;
  std::vector<std::unique_ptr<btRigidBody>> rigid_;
};

btVector3 centroid(const btSoftBody& body);
/// Hash of every node position (bit patterns), to compare runs.
std::size_t positionHash(const btAlignedObjectArray<btSoftBody*>& bodies);

/// The recall scenes, small: each adds its bodies to `world` (which must have no gravity for the
/// first three; the pile sets its own floor).
enum class Scene { HeadOn, ThreeInARow, Concave, Pile };
const char* sceneName(Scene scene);
void buildScene(Scene scene, SoftWorld& world, bool vf_ss = true);
int sceneSteps(Scene scene);
double sceneGravity(Scene scene);

}  // namespace psc_test
