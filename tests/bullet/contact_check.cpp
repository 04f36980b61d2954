#include "contact_check.h"

#include "ground_truth.h"

#include <cmath>
#include <cstdio>
#include <cstring>
#include <set>
#include <utility>

// See bullet_plugin/src/exact_stage.cpp: GCC reports a false maybe-uninitialized at Bullet's lines.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <BulletSoftBody/btSoftBodyInternals.h>
#pragma GCC diagnostic pop

namespace psc_test {
namespace {

/// Bit for bit: a NaN equals the same NaN, and +0 differs from −0.
bool sameBits(btScalar a, btScalar b) { return std::memcmp(&a, &b, sizeof a) == 0; }
bool sameVector(const btVector3& a, const btVector3& b) {
  return sameBits(a.x(), b.x()) && sameBits(a.y(), b.y()) && sameBits(a.z(), b.z());
}

int ownerOfFace(const btAlignedObjectArray<btSoftBody*>& bodies, const btSoftBody::Face* face) {
  for (int b = 0; b < bodies.size(); ++b) {
    const btSoftBody& body = *bodies[b];
    if (body.m_faces.size() > 0 && face >= &body.m_faces[0] && face < &body.m_faces[0] + body.m_faces.size()) return b;
  }
  return -1;
}

Vec3 toVec(const btVector3& v) { return {double(v.x()), double(v.y()), double(v.z())}; }

}  // namespace

bool sameContact(const btSoftBody::SContact& a, const btSoftBody::SContact& b) {
  return a.m_node == b.m_node && a.m_face == b.m_face && sameVector(a.m_weights, b.m_weights) &&
         sameVector(a.m_normal, b.m_normal) && sameBits(a.m_margin, b.m_margin) && sameBits(a.m_friction, b.m_friction) &&
         sameBits(a.m_cfm[0], b.m_cfm[0]) && sameBits(a.m_cfm[1], b.m_cfm[1]);
}

bool inBand(const btSoftBody::SContact& c, btScalar margins) {
  const btSoftBody::Face& f = *c.m_face;
  const btVector3 p = f.m_n[0]->m_x * c.m_weights.x() + f.m_n[1]->m_x * c.m_weights.y() + f.m_n[2]->m_x * c.m_weights.z();
  return (c.m_node->m_x - p).length2() >= margins * margins;
}

/// `made` is Bullet's contact `bullets` with both weights divided by one whole k ≥ 2, in the band.
bool sharedWeight(const btSoftBody::SContact& bullets, const btSoftBody::SContact& made, btScalar margins) {
  btSoftBody::SContact restored = made;
  restored.m_cfm[0] = bullets.m_cfm[0];
  restored.m_cfm[1] = bullets.m_cfm[1];
  if (!sameContact(bullets, restored)) return false;
  const btScalar reference = bullets.m_cfm[0] != 0 ? bullets.m_cfm[0] : bullets.m_cfm[1];
  const btScalar shared = bullets.m_cfm[0] != 0 ? made.m_cfm[0] : made.m_cfm[1];
  if (!(shared > 0)) return false;
  const long k = std::lround(double(reference) / double(shared));
  if (k < 2 || !sameBits(made.m_cfm[0], bullets.m_cfm[0] / btScalar(k)) ||
      !sameBits(made.m_cfm[1], bullets.m_cfm[1] / btScalar(k)))
    return false;
  return inBand(made, margins);
}

ContactAudit auditContacts(const btAlignedObjectArray<btSoftBody*>& bodies) {
  ContactAudit audit;
  auto problem = [&](const std::string& what) {
    if (audit.first_problem.empty()) audit.first_problem = what;
  };
  for (int a = 0; a < bodies.size(); ++a) {
    btSoftBody& body = *bodies[a];
    const int count = body.m_scontacts.size();
    std::set<std::pair<const void*, const void*>> seen;
    for (int i = 0; i < count; ++i) {
      const btSoftBody::SContact c = body.m_scontacts[i];
      ++audit.contacts;
      if (!seen.insert({c.m_node, c.m_face}).second) {
        ++audit.duplicates;
        problem("duplicate contact in body " + std::to_string(a));
      }
      const int b = ownerOfFace(bodies, c.m_face);
      if (b < 0 || b == a) {
        ++audit.foreign_faces;
        problem("contact of body " + std::to_string(a) + " with a face of body " + std::to_string(b));
        continue;
      }
      btSoftBody& other = *bodies[b];
      const double margins = double(body.getCollisionShape()->getMargin()) + double(other.getCollisionShape()->getMargin());
      const double radius = margins + 2.0 * (toVec(c.m_node->m_x) - toVec(c.m_node->m_q)).norm();
      const double d = pointTriangleDistance(toVec(c.m_node->m_x), toVec(c.m_face->m_n[0]->m_x),
                                             toVec(c.m_face->m_n[1]->m_x), toVec(c.m_face->m_n[2]->m_x));
      if (!(d < radius * (1.0 + kRadiusTolerance) + 1e-6)) {
        ++audit.outside_radius;
        problem("contact at distance " + std::to_string(d) + " beyond radius " + std::to_string(radius));
      }
      btSoftColliders::CollideVF_SS collide;
      collide.mrg = body.getCollisionShape()->getMargin() + other.getCollisionShape()->getMargin();
      collide.psb[0] = &body;
      collide.psb[1] = &other;
      btDbvtNode node_leaf{};
      btDbvtNode face_leaf{};
      node_leaf.data = c.m_node;
      face_leaf.data = c.m_face;
      collide.Process(&node_leaf, &face_leaf);
      if (body.m_scontacts.size() != count + 1) {
        ++audit.field_mismatches;
        problem("CollideVF_SS refuses a contact the plugin made");
      } else if (!sameContact(body.m_scontacts[count], c)) {
        if (sharedWeight(body.m_scontacts[count], c, collide.mrg)) {
          ++audit.shared_weights;
        } else {
          ++audit.field_mismatches;
          problem("contact differs from CollideVF_SS's for the same (node, face)");
        }
      }
      body.m_scontacts.resize(count);
    }
  }
  return audit;
}

}  // namespace psc_test
