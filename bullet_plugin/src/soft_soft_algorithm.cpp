#include "soft_soft_algorithm.h"

#include "installation.h"

#include <BulletCollision/CollisionDispatch/btCollisionConfiguration.h>
#include <BulletCollision/CollisionDispatch/btCollisionDispatcher.h>
#include <BulletCollision/CollisionDispatch/btCollisionObjectWrapper.h>
#include <BulletSoftBody/btSoftBody.h>
#include <LinearMath/btPoolAllocator.h>

#include <new>

namespace psc::bullet::detail {

SoftSoftAlgorithm::SoftSoftAlgorithm(const btCollisionAlgorithmConstructionInfo& info, Installation& owner)
    : btCollisionAlgorithm(info), owner_(owner) {
  owner_.algorithmCreated();
}

SoftSoftAlgorithm::~SoftSoftAlgorithm() {
  if (fallback_ != nullptr) {
    fallback_->~btCollisionAlgorithm();
    m_dispatcher->freeCollisionAlgorithm(fallback_);
  }
  owner_.algorithmDestroyed();
}

void SoftSoftAlgorithm::processCollision(const btCollisionObjectWrapper* body0, const btCollisionObjectWrapper* body1,
                                         const btDispatcherInfo& info, btManifoldResult* result) {
  auto* soft0 = const_cast<btSoftBody*>(btSoftBody::upcast(body0->getCollisionObject()));
  auto* soft1 = const_cast<btSoftBody*>(btSoftBody::upcast(body1->getCollisionObject()));
  if (soft0 != nullptr && soft1 != nullptr && owner_.collide(*soft0, *soft1)) return;
  if (fallback_ == nullptr) {
    btCollisionAlgorithmCreateFunc* create = owner_.previousCreateFunc();
    if (create == nullptr) return;
    btCollisionAlgorithmConstructionInfo fallback_info(m_dispatcher, 0);
    fallback_ = create->CreateCollisionAlgorithm(fallback_info, body0, body1);
    if (fallback_ == nullptr) return;
  }
  owner_.collideFallback(*fallback_, body0, body1, info, result);
}

btScalar SoftSoftAlgorithm::calculateTimeOfImpact(btCollisionObject* body0, btCollisionObject* body1,
                                                  const btDispatcherInfo& info, btManifoldResult* result) {
  // Bullet's btSoftSoftCollisionAlgorithm has no time of impact either ("not yet").
  if (fallback_ != nullptr) return fallback_->calculateTimeOfImpact(body0, body1, info, result);
  return btScalar(1);
}

void SoftSoftAlgorithm::getAllContactManifolds(btManifoldArray& manifolds) {
  if (fallback_ != nullptr) fallback_->getAllContactManifolds(manifolds);
}

btCollisionAlgorithm* SoftSoftCreateFunc::CreateCollisionAlgorithm(btCollisionAlgorithmConstructionInfo& info,
                                                                   const btCollisionObjectWrapper*,
                                                                   const btCollisionObjectWrapper*) {
  // The dispatcher's pool has fixed-size slots and does not check the size it is asked for; a
  // larger object goes to btAlignedAlloc, which freeCollisionAlgorithm also recognises.
  auto* dispatcher = static_cast<btCollisionDispatcher*>(info.m_dispatcher1);
  const btPoolAllocator* pool = dispatcher->getCollisionConfiguration()->getCollisionAlgorithmPool();
  const int size = static_cast<int>(sizeof(SoftSoftAlgorithm));
  void* memory = (pool != nullptr && size <= pool->getElementSize())
                     ? dispatcher->allocateCollisionAlgorithm(size)
                     : btAlignedAlloc(sizeof(SoftSoftAlgorithm), 16);
  return new (memory) SoftSoftAlgorithm(info, owner_);
}

}  // namespace psc::bullet::detail
