#include "precision_guard.h"

#include <BulletSoftBody/btSoftBody.h>

namespace psc::bullet::detail {
namespace {

using PredictMotion = void (btSoftBody::*)(btScalar);

}  // namespace

// btSoftBody::predictMotion(btScalar) is _ZN10btSoftBody13predictMotionEf in libBulletSoftBody
// and ...Ed in libBulletSoftBody-float64. Holding its address makes linking this plugin against
// the other build fail with an undefined reference naming it; without the guard such a program
// links and corrupts memory (docs/BULLET.md). volatile keeps the optimiser from dropping it.
extern const volatile PredictMotion kPredictMotionOfThisPrecision;
const volatile PredictMotion kPredictMotionOfThisPrecision = &btSoftBody::predictMotion;

bool precisionGuardLinked() { return kPredictMotionOfThisPrecision != nullptr; }

}  // namespace psc::bullet::detail
