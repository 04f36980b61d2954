// Exactness: every contact the plugin produces passes Bullet's exact predicate, equals field for
// field what CollideVF_SS gives for the same (node, face), and equals the contact Bullet's own
// default handler (btSoftBody::defaultCollisionHandler, the VF_SS tree path) makes for it.
#include "contact_check.h"
#include "ground_truth.h"
#include "psc/bullet/bullet.h"
#include "soft_world.h"

#include <gtest/gtest.h>

#include <map>
#include <utility>

namespace {

using psc_test::Scene;

TEST(Exactness, EveryContactIsCollideVfSsOwn) {
  for (Scene scene : {Scene::ThreeInARow, Scene::Concave}) {
    psc_test::SoftWorld w(psc_test::sceneGravity(scene));
    psc_test::buildScene(scene, w);
    auto plugin = psc::bullet::install(w.world);
    std::size_t contacts = 0;
    w.run(30, [&] {
      const psc_test::ContactAudit audit = psc_test::auditContacts(w.world.getSoftBodyArray());
      contacts += audit.contacts;
      EXPECT_TRUE(audit.clean()) << psc_test::sceneName(scene) << ": " << audit.first_problem;
      EXPECT_EQ(audit.contacts, plugin.stats().contacts);
    });
    EXPECT_GT(contacts, 1000u) << psc_test::sceneName(scene);
  }
}

TEST(Exactness, ContactsEqualBulletsDefaultPathForTheSameNodeAndFace) {
  psc_test::SoftWorld w(0);
  psc_test::buildScene(Scene::HeadOn, w);
  auto plugin = psc::bullet::install(w.world);
  std::size_t compared = 0, plugin_contacts = 0, bullet_contacts = 0;
  w.run(25, [&] {
    btSoftBody* a = w.world.getSoftBodyArray()[0];
    btSoftBody* b = w.world.getSoftBodyArray()[1];
    const int na = a->m_scontacts.size(), nb = b->m_scontacts.size();
    std::map<std::pair<const void*, const void*>, btSoftBody::SContact> ours;
    for (int i = 0; i < na; ++i) ours[{a->m_scontacts[i].m_node, a->m_scontacts[i].m_face}] = a->m_scontacts[i];
    for (int i = 0; i < nb; ++i) ours[{b->m_scontacts[i].m_node, b->m_scontacts[i].m_face}] = b->m_scontacts[i];
    plugin_contacts += ours.size();
    // Bullet's own VF_SS path on the same state, appended after ours and removed again.
    a->defaultCollisionHandler(b);
    auto compare = [&](btSoftBody* body, int from) {
      for (int i = from; i < body->m_scontacts.size(); ++i) {
        ++bullet_contacts;
        const btSoftBody::SContact& theirs = body->m_scontacts[i];
        const auto it = ours.find({theirs.m_node, theirs.m_face});
        ASSERT_NE(it, ours.end()) << "Bullet found a contact the plugin did not";
        EXPECT_TRUE(psc_test::sameContact(it->second, theirs));
        ++compared;
      }
      body->m_scontacts.resize(from);
    };
    compare(a, na);
    compare(b, nb);
  });
  EXPECT_GT(compared, 500u);
  std::printf("exactness: %zu contacts of Bullet's default path compared field for field; the plugin found %zu, "
              "Bullet %zu\n", compared, plugin_contacts, bullet_contacts);
}

}  // namespace
