// Bullet's default soft-body solver with one addition: right after each body predicts its motion,
// the attached plugin refits that body's sensor boxes while its nodes are still in the cache.
//
//   psc::bullet::SoftBodySolver solver;                     // outlives the world, like any solver
//   btSoftRigidDynamicsWorld world(&dispatcher, &broadphase, &constraints, &config, &solver);
//   auto plugin = psc::bullet::install(world);
//   plugin.attach(solver);                                  // optional: a faster sensor step
//
// Without it the plugin refits every body at the step's first soft-soft pair, reading all nodes
// again from memory; with it the same boxes come out (same candidates, same contacts) for less.
#pragma once

#include "psc/bullet/precision.h"

#include <BulletSoftBody/btDefaultSoftBodySolver.h>

namespace psc::bullet {

class Installation;

class SoftBodySolver : public btDefaultSoftBodySolver {
 public:
  SoftBodySolver() = default;
  ~SoftBodySolver() override;  ///< detaches from its plugin
  SoftBodySolver(const SoftBodySolver&) = delete;
  SoftBodySolver& operator=(const SoftBodySolver&) = delete;

  /// What btDefaultSoftBodySolver::predictMotion does (each active body predicts its motion), with
  /// the attached plugin's Plugin::afterPredictMotion right after each body's.
  void predictMotion(btScalar dt) override;
  bool attached() const { return installation_ != nullptr; }

 private:
  friend class Installation;
  Installation* installation_ = nullptr;
};

}  // namespace psc::bullet
