// Compile-time half of the precision guard. Bullet's float and double builds have different
// layouts for every type that holds a btScalar, and mixing them links silently and corrupts memory
// (docs/BULLET.md). Every public header of psc::bullet includes this one, so a translation
// unit whose Bullet precision differs from the plugin's stops here with a message. The link-time
// half lives in src/precision_guard.cpp and in the precision tag of install().
#pragma once

#include "psc/bullet/config.h"

#include <LinearMath/btScalar.h>

#if defined(BT_USE_DOUBLE_PRECISION) && !PSC_BULLET_DOUBLE_PRECISION
#error "psc::bullet was built for single-precision Bullet (pkg-config bullet), but this code defines BT_USE_DOUBLE_PRECISION: build psc with -DPSC_BULLET_DOUBLE=ON, or use single-precision Bullet"
#elif !defined(BT_USE_DOUBLE_PRECISION) && PSC_BULLET_DOUBLE_PRECISION
#error "psc::bullet was built for double-precision Bullet (pkg-config bullet-float64), but this code does not define BT_USE_DOUBLE_PRECISION: build psc with -DPSC_BULLET_DOUBLE=OFF, or use bullet-float64"
#endif

namespace psc::bullet {

/// Part of install()'s signature: its mangled name names the scalar type, so a program whose
/// btScalar differs from the plugin's cannot link even if it got past the check above.
template <class Scalar>
struct PrecisionTag {};

static_assert(sizeof(btScalar) == (PSC_BULLET_DOUBLE_PRECISION ? sizeof(double) : sizeof(float)),
              "psc::bullet: btScalar differs from the precision the plugin was built for");

}  // namespace psc::bullet
