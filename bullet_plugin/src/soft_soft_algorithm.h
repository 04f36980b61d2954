// Private: the btCollisionAlgorithm the plugin registers for (SOFTBODY, SOFTBODY) pairs.
#pragma once

#include <BulletCollision/BroadphaseCollision/btCollisionAlgorithm.h>
#include <BulletCollision/CollisionDispatch/btCollisionCreateFunc.h>

namespace psc::bullet {

class Installation;

namespace detail {

/// Hands the pair to the installation, which collides it from the sensors' candidates; when the
/// installation declines (a body does not participate, or the core rejected the step) the pair
/// goes to the algorithm that was registered before install(), created on first need.
class SoftSoftAlgorithm final : public btCollisionAlgorithm {
 public:
  SoftSoftAlgorithm(const btCollisionAlgorithmConstructionInfo& info, Installation& owner);
  ~SoftSoftAlgorithm() override;
  SoftSoftAlgorithm(const SoftSoftAlgorithm&) = delete;
  SoftSoftAlgorithm& operator=(const SoftSoftAlgorithm&) = delete;

  void processCollision(const btCollisionObjectWrapper* body0, const btCollisionObjectWrapper* body1,
                        const btDispatcherInfo& info, btManifoldResult* result) override;
  btScalar calculateTimeOfImpact(btCollisionObject* body0, btCollisionObject* body1, const btDispatcherInfo& info,
                                 btManifoldResult* result) override;
  /// Soft contacts live in btSoftBody::m_scontacts, not in manifolds; the fallback may own some.
  void getAllContactManifolds(btManifoldArray& manifolds) override;

  const Installation& owner() const { return owner_; }

 private:
  Installation& owner_;
  btCollisionAlgorithm* fallback_ = nullptr;
};

class SoftSoftCreateFunc final : public btCollisionAlgorithmCreateFunc {
 public:
  explicit SoftSoftCreateFunc(Installation& owner) : owner_(owner) {}
  btCollisionAlgorithm* CreateCollisionAlgorithm(btCollisionAlgorithmConstructionInfo& info,
                                                 const btCollisionObjectWrapper* body0,
                                                 const btCollisionObjectWrapper* body1) override;
  const Installation& owner() const { return owner_; }

 private:
  Installation& owner_;
};

}  // namespace detail
}  // namespace psc::bullet
