// Private: Bullet's own vertex-face test on the core's candidate pairs.
#pragma once

#include "psc/world.h"

class btSoftBody;

namespace psc::bullet::detail {

struct ExactCounters {
  std::size_t tests = 0;
  std::size_t contacts = 0;
};

/// Runs btSoftColliders::CollideVF_SS on each candidate (node of `node_body`, face of `face_body`)
/// in [first, last), exactly as btSoftBody::defaultCollisionHandler's tree traversal would for the
/// same pair: margin = both collision margins, contacts pushed into node_body->m_scontacts.
/// The candidates' indices must be valid for the bodies' current m_nodes / m_faces.
void collideCandidates(btSoftBody& node_body, btSoftBody& face_body, const psc::CandidatePair* first,
                       const psc::CandidatePair* last, ExactCounters& counters);

}  // namespace psc::bullet::detail
