// Private: reads the create func a btCollisionDispatcher currently uses for a pair of proxy types.
#pragma once

#include <BulletCollision/CollisionDispatch/btCollisionDispatcher.h>

namespace psc::bullet::detail {

/// btCollisionDispatcher has a setter for its double-dispatch table but no getter, and uninstall
/// must give back exactly what was registered before (the user's own create func, if any, not the
/// configuration's default). A pointer to the protected member formed in a derived class is
/// standard C++; the class is never instantiated.
struct DispatcherAccess : btCollisionDispatcher {
  static btCollisionAlgorithmCreateFunc* contactCreateFunc(const btCollisionDispatcher& dispatcher, int type0,
                                                           int type1) {
    return (dispatcher.*(&DispatcherAccess::m_doubleDispatchContactPoints))[type0][type1];
  }
};

}  // namespace psc::bullet::detail
