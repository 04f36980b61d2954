// Private: the link-time half of the precision guard.
#pragma once

namespace psc::bullet::detail {

/// Always true. Calling it from install() pulls precision_guard.o, and with it a reference to a
/// btScalar-taking Bullet symbol, into every program that uses the plugin.
bool precisionGuardLinked();

}  // namespace psc::bullet::detail
