// Checks that soft contacts are exactly what Bullet's own CollideVF_SS makes for their (node, face).
#pragma once

#include <BulletSoftBody/btSoftBody.h>

#include <cstddef>
#include <string>

namespace psc_test {

struct ContactAudit {
  std::size_t contacts = 0;
  std::size_t outside_radius = 0;    ///< fails Bullet's predicate (distance ≥ its radius, with tolerance)
  std::size_t field_mismatches = 0;  ///< differs from CollideVF_SS's contact for the same (node, face)
  std::size_t foreign_faces = 0;     ///< face of no body in the array, or of the node's own body
  std::size_t duplicates = 0;        ///< the same (node, face) twice in a step
  std::string first_problem;
  bool clean() const { return outside_radius == 0 && field_mismatches == 0 && foreign_faces == 0 && duplicates == 0; }
};

/// Audits every SContact in the bodies' m_scontacts: the exact distance (double) is within
/// Bullet's acceptance radius, and rerunning btSoftColliders::CollideVF_SS on the same (node,
/// face) gives a contact equal field for field (bit for bit). Leaves m_scontacts as it was.
ContactAudit auditContacts(const btAlignedObjectArray<btSoftBody*>& bodies);

/// Field for field, bit for bit (a NaN normal equals the same NaN; +0 and −0 differ).
bool sameContact(const btSoftBody::SContact& a, const btSoftBody::SContact& b);

}  // namespace psc_test
