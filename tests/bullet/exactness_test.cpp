// Exactness: every contact the plugin produces passes Bullet's exact predicate, equals field for
// field what CollideVF_SS gives for the same (node, face), and equals the contact Bullet's own
// default handler (btSoftBody::defaultCollisionHandler, the VF_SS tree path) makes for it; where
// the plugin shared a node's band weight (Settings::crowded_band, runaway_sharing), Bullet's
// contact with both m_cfm divided by the same whole number.
#include "contact_check.h"
#include "ground_truth.h"
#include "psc/bullet/bullet.h"
#include "soft_world.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <map>
#include <utility>

namespace {

using psc_test::Scene;

TEST(Exactness, EveryContactIsCollideVfSsOwn) {
  // With the default settings a contact may carry a shared band weight (Settings::crowded_band,
  // runaway_sharing: Bullet's m_cfm divided by a whole k, counted in shared_weights); with both off
  // every contact is CollideVF_SS's own, bit for bit.
  for (bool sharing : {true, false}) {
    for (Scene scene : {Scene::ThreeInARow, Scene::Concave}) {
      psc_test::SoftWorld w(psc_test::sceneGravity(scene));
      psc_test::buildScene(scene, w);
      psc::bullet::Settings settings;
      if (!sharing) {
        settings.crowded_band = 0;
        settings.runaway_sharing = false;
      }
      auto plugin = psc::bullet::install(w.world, settings);
      std::size_t contacts = 0, shared = 0;
      w.run(30, [&] {
        const psc_test::ContactAudit audit = psc_test::auditContacts(w.world.getSoftBodyArray());
        contacts += audit.contacts;
        shared += audit.shared_weights;
        EXPECT_TRUE(audit.clean()) << psc_test::sceneName(scene) << ": " << audit.first_problem;
        EXPECT_EQ(audit.contacts, plugin.stats().contacts);
        EXPECT_EQ(audit.shared_weights, plugin.stats().shared_contacts);
      });
      EXPECT_GT(contacts, 1000u) << psc_test::sceneName(scene);
      if (!sharing) {
        EXPECT_EQ(shared, 0u) << psc_test::sceneName(scene);
      }
      std::printf("exactness, %s, sharing %s: %zu contacts, %zu with a shared band weight\n",
                  psc_test::sceneName(scene), sharing ? "on" : "off", contacts, shared);
    }
  }
}

TEST(Exactness, ContactsEqualBulletsDefaultPathForTheSameNodeAndFace) {
  psc_test::SoftWorld w(0);
  psc_test::buildScene(Scene::HeadOn, w);
  auto plugin = psc::bullet::install(w.world);
  std::size_t compared = 0, plugin_contacts = 0, bullet_contacts = 0, shared = 0;
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
        // The same contact, or (Settings::crowded_band, runaway_sharing) Bullet's with its band
        // weight shared.
        const btScalar margins = a->getCollisionShape()->getMargin() + b->getCollisionShape()->getMargin();
        const bool same = psc_test::sameContact(it->second, theirs);
        EXPECT_TRUE(same || psc_test::sharedWeight(theirs, it->second, margins));
        shared += same ? 0 : 1;
        ++compared;
      }
      body->m_scontacts.resize(from);
    };
    compare(a, na);
    compare(b, nb);
  });
  EXPECT_GT(compared, 500u);
  std::printf("exactness: %zu contacts of Bullet's default path compared field for field (%zu with a shared band "
              "weight); the plugin found %zu, Bullet %zu\n", compared, shared, plugin_contacts, bullet_contacts);
}

}  // namespace
