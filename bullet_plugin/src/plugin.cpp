#include "psc/bullet/plugin.h"

#include "installation.h"
#include "precision_guard.h"
#include "psc/error.h"
#include "psc/bullet/solver.h"

#include <cassert>
#include <utility>

namespace psc::bullet {

Plugin::Plugin(std::unique_ptr<Installation> installation) : impl_(std::move(installation)) {}
Plugin::Plugin() = default;
Plugin::~Plugin() = default;
Plugin::Plugin(Plugin&&) noexcept = default;
Plugin& Plugin::operator=(Plugin&&) noexcept = default;

void Plugin::uninstall() { impl_.reset(); }

void Plugin::setEnabled(const btSoftBody* body, bool enabled) {
  if (impl_) impl_->setEnabled(body, enabled);
}

void Plugin::clearEnabled(const btSoftBody* body) {
  if (impl_) impl_->setEnabled(body, std::nullopt);
}

void Plugin::setSelfCollision(const btSoftBody* body, bool on) {
  if (impl_) impl_->setSelfCollision(body, on);
}

bool Plugin::participates(const btSoftBody* body) const {
  return impl_ && body != nullptr && impl_->participates(*body);
}

void Plugin::refreshBody(const btSoftBody* body) {
  if (impl_) impl_->refreshBody(body);
}

void Plugin::afterPredictMotion(const btSoftBody& body) {
  if (impl_) impl_->afterPredictMotion(body);
}

void Plugin::attach(SoftBodySolver& solver) {
  if (!impl_) throw psc::Error(psc::ErrorCode::InvalidArgument, "psc::bullet::Plugin::attach: not installed");
  impl_->attach(solver);
}

SoftBodySolver::~SoftBodySolver() {
  if (installation_ != nullptr) installation_->detach(*this);
}

void SoftBodySolver::predictMotion(btScalar dt) {
  // btDefaultSoftBodySolver::predictMotion in Bullet 3.24: every active body, in the set's order.
  for (int i = 0; i < m_softBodySet.size(); ++i) {
    btSoftBody* body = m_softBodySet[i];
    if (!body->isActive()) continue;
    body->predictMotion(dt);
    if (installation_ != nullptr) installation_->afterPredictMotion(*body);
  }
}

const Stats& Plugin::stats() const {
  static const Stats kNothing;
  return impl_ ? impl_->stats() : kNothing;
}

const psc::SensorWorld& Plugin::sensorWorld() const {
  if (!impl_) throw psc::Error(psc::ErrorCode::InvalidArgument, "psc::bullet::Plugin: not installed");
  return impl_->sensorWorld();
}

std::optional<psc::BodyId> Plugin::bodyId(const btSoftBody* body) const {
  return impl_ ? impl_->bodyId(body) : std::nullopt;
}

bool Plugin::owns(const btCollisionAlgorithm* algorithm) const { return impl_ && impl_->owns(algorithm); }

Plugin install(btSoftRigidDynamicsWorld& world, const Settings& settings, PrecisionTag<btScalar>) {
  const bool guard = detail::precisionGuardLinked();
  assert(guard);
  (void)guard;
  return Plugin(std::make_unique<Installation>(world, settings));
}

}  // namespace psc::bullet
