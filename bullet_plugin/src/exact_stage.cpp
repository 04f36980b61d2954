#include "exact_stage.h"

// CollideVF_SS leaves its projection point uninitialised when the face is degenerate (it then
// never reads it); GCC's -Wmaybe-uninitialized sees that once the header is inlined here, and it
// reports at the header's lines, so the region must enclose Bullet's first inclusion in this file.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <BulletSoftBody/btSoftBody.h>
#include <BulletSoftBody/btSoftBodyInternals.h>
#pragma GCC diagnostic pop

#include <cassert>

namespace psc::bullet::detail {

void collideCandidates(btSoftBody& node_body, btSoftBody& face_body, const psc::CandidatePair* first,
                       const psc::CandidatePair* last, ExactCounters& counters) {
  if (first == last) return;
  btSoftColliders::CollideVF_SS collide;
  collide.mrg = node_body.getCollisionShape()->getMargin() + face_body.getCollisionShape()->getMargin();
  collide.psb[0] = &node_body;
  collide.psb[1] = &face_body;
  // CollideVF_SS::Process only reads the leaves' data pointers, so two stub leaves stand in for
  // the trees' leaves (verified to reproduce Bullet's contacts field for field).
  btDbvtNode node_leaf{};
  btDbvtNode face_leaf{};
  const int before = node_body.m_scontacts.size();
  for (const psc::CandidatePair* c = first; c != last; ++c) {
    assert(static_cast<int>(c->vertex) < node_body.m_nodes.size());
    assert(static_cast<int>(c->triangle) < face_body.m_faces.size());
    node_leaf.data = &node_body.m_nodes[static_cast<int>(c->vertex)];
    face_leaf.data = &face_body.m_faces[static_cast<int>(c->triangle)];
    collide.Process(&node_leaf, &face_leaf);
  }
  counters.tests += static_cast<std::size_t>(last - first);
  counters.contacts += static_cast<std::size_t>(node_body.m_scontacts.size() - before);
}

}  // namespace psc::bullet::detail
