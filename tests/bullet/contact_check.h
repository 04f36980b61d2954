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
  /// Equal to CollideVF_SS's contact but for m_cfm[0] and m_cfm[1], both Bullet's divided by the
  /// same whole k ≥ 2, with the node beyond the margins from its face point: a band contact whose
  /// weight the plugin shared (psc::bullet::shareBandWeights; Settings::runaway_sharing and
  /// Settings::crowded_band). Not a problem; counted so that tests can ask for none.
  std::size_t shared_weights = 0;
  std::size_t foreign_faces = 0;     ///< face of no body in the array, or of the node's own body
  std::size_t duplicates = 0;        ///< the same (node, face) twice in a step
  std::string first_problem;
  bool clean() const { return outside_radius == 0 && field_mismatches == 0 && foreign_faces == 0 && duplicates == 0; }
};

/// Audits every SContact in the bodies' m_scontacts: the exact distance (double) is within
/// Bullet's acceptance radius, and rerunning btSoftColliders::CollideVF_SS on the same (node,
/// face) gives a contact equal field for field (bit for bit), or one whose band weight was shared
/// (ContactAudit::shared_weights). Leaves m_scontacts as it was.
ContactAudit auditContacts(const btAlignedObjectArray<btSoftBody*>& bodies);

/// Field for field, bit for bit (a NaN normal equals the same NaN; +0 and −0 differ).
bool sameContact(const btSoftBody::SContact& a, const btSoftBody::SContact& b);

/// The contact lies in the band psc::bullet::shareBandWeights shares: its node at least `margins`
/// from its face point at the contact's weights, measured in btScalar as the function does.
bool inBand(const btSoftBody::SContact& c, btScalar margins);

/// `made` is Bullet's contact `bullets` (same node and face) but for a shared band weight: both
/// m_cfm divided by one whole k ≥ 2, and its node at least `margins` from its face point at the
/// contact's weights, in btScalar (psc::bullet::shareBandWeights).
bool sharedWeight(const btSoftBody::SContact& bullets, const btSoftBody::SContact& made, btScalar margins);

}  // namespace psc_test
