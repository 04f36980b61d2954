// Self-collision through the plugin (Settings::self_collision, Plugin::setSelfCollision): a cloth
// lying flat gets no self contacts; the same cloth folded so that its halves are within the
// margins gets self contacts from Bullet's own CollideVF_SS, only where switched on.
#include "psc/bullet/bullet.h"
#include "psc/shapes.h"
#include "soft_world.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <set>
#include <utility>
#include <vector>

namespace {

constexpr double kPi = 3.14159265358979323846;

int selfContacts(const btSoftBody& body) {
  int n = 0;
  for (int i = 0; i < body.m_scontacts.size(); ++i) {
    const btSoftBody::Face* f = body.m_scontacts[i].m_face;
    n += body.m_faces.size() > 0 && f >= &body.m_faces[0] && f < &body.m_faces[0] + body.m_faces.size();
  }
  return n;
}

/// Folds the cloth's nodes (x > 0) over a cylinder of radius rho: the halves end 2·rho apart.
void fold(btSoftBody& cloth, double rho) {
  for (int i = 0; i < cloth.m_nodes.size(); ++i) {
    btVector3& x = cloth.m_nodes[i].m_x;
    const double s = double(x.x());
    if (s <= 0.0) continue;
    const double y = double(x.y());
    if (s <= kPi * rho) {
      x = btVector3(btScalar(rho * std::sin(s / rho)), btScalar(y), btScalar(rho * (1.0 - std::cos(s / rho))));
    } else {
      x = btVector3(btScalar(-(s - kPi * rho)), btScalar(y), btScalar(2.0 * rho));
    }
    cloth.m_nodes[i].m_q = x;
    cloth.m_nodes[i].m_v = btVector3(0, 0, 0);
  }
}

struct Folding {
  psc_test::SoftWorld w{0};
  btSoftBody* cloth = nullptr;
  Folding() {
    psc_test::SoftParams params;
    params.margin = 0.02;
    params.shape_matching = 0;
    cloth = w.addSoft(psc::makePatch(2.0, 1.0, 41, 21), params);
  }
};

TEST(SelfCollision, FoldedClothGetsSelfContactsOnlyWhereSwitchedOn) {
  for (const bool on : {false, true}) {
    Folding f;
    psc::bullet::Settings settings;
    settings.self_collision = on;
    auto plugin = psc::bullet::install(f.w.world, settings);
    int flat = -1, folded = -1;
    f.w.run(1, [&] { flat = selfContacts(*f.cloth); });  // the flat cloth is the rest shape
    EXPECT_EQ(flat, 0) << "a flat cloth must not touch itself";
    fold(*f.cloth, 0.015);
    f.w.run(1, [&] { folded = selfContacts(*f.cloth); });
    if (on) {
      EXPECT_GT(folded, 100) << "the folded halves are within the margins";
      EXPECT_EQ(std::size_t(folded), plugin.stats().self_contacts);
      EXPECT_GT(plugin.stats().self_exact_tests, 0u);
      EXPECT_EQ(plugin.stats().self_bodies, 1u);
    } else {
      EXPECT_EQ(folded, 0) << "Bullet's world has no vertex-face self-collision";
      EXPECT_EQ(plugin.stats().self_contacts, 0u);
    }
  }
}

TEST(SelfCollision, NearestFaceKeepsOneSelfContactPerNode) {
  // ContactSet::NearestFace on a body against itself: every node of the folded cloth that gets self
  // contacts with all pairs keeps exactly one, and the rest are counted out. With Robust the core's
  // nearest candidates give the contacts Bullet's test gives on all candidates (no face is small).
  using psc::bullet::ContactSet;
  using psc::bullet::ExactTest;
  std::vector<std::set<long>> nodes;  // indices of the nodes with a self contact, per run
  std::vector<std::size_t> counts;
  for (const auto& [exact, set] : {std::make_pair(ExactTest::Bullet, ContactSet::AllPairs),
                                   std::make_pair(ExactTest::Bullet, ContactSet::NearestFace),
                                   std::make_pair(ExactTest::Robust, ContactSet::NearestFace)}) {
    Folding f;
    psc::bullet::Settings settings;
    settings.self_collision = true;
    settings.exact = exact;
    settings.contacts = set;
    auto plugin = psc::bullet::install(f.w.world, settings);
    f.w.run(1);
    fold(*f.cloth, 0.015);
    std::size_t folded = 0, reduced = 0;
    std::set<long> with_contact;
    f.w.run(1, [&] {
      folded = std::size_t(selfContacts(*f.cloth));
      reduced = plugin.stats().reduced_contacts;
      for (int i = 0; i < f.cloth->m_scontacts.size(); ++i)
        with_contact.insert(long(f.cloth->m_scontacts[i].m_node - &f.cloth->m_nodes[0]));
    });
    std::printf("%s, %s: %zu self contacts on %zu nodes, %zu reduced after the exact test\n",
                psc::bullet::toString(exact), psc::bullet::toString(set), folded, with_contact.size(), reduced);
    if (set == ContactSet::NearestFace) {
      EXPECT_EQ(folded, with_contact.size()) << "one self contact per node";
      // With Bullet's test every candidate is tested and the reduction counts the rest; with
      // Robust the core hands over only the nearest candidates (and near ties) to begin with.
      if (exact == ExactTest::Bullet) {
        EXPECT_EQ(folded + reduced, counts.front()) << "what the reduction left out is counted";
      }
    } else {
      EXPECT_EQ(reduced, 0u);
    }
    nodes.push_back(with_contact);
    counts.push_back(folded);
  }
  EXPECT_GT(counts[0], counts[1]) << "a folded node is within the radius of several faces";
  EXPECT_EQ(nodes[0], nodes[1]) << "no node loses its self contact";
  EXPECT_EQ(nodes[1], nodes[2]);
  EXPECT_EQ(counts[1], counts[2]);
}

TEST(SelfCollision, ASelfContactsMarginIsTheSelfRuleNotTheBodysSpeed) {
  // A folded cloth whose top layer comes down at 0.3 m/s, the whole cloth at rest or sliding at
  // 10 m/s along its fold (the same physics). Bullet's test makes a contact's margin margins +
  // 2·|m_x − m_q|, the distance the solver pushes the node out to: for a self contact that is the
  // body's speed, and the sliding cloth's layers were pushed from 0.03 to 0.36 apart in three
  // steps (a review's finding). A self contact's margin is now the self rule's radius,
  // selfRadius + 2·selfMotion, and both runs end with their layers alike.
  const double rho = 0.015;
  std::vector<double> gaps, widests;
  for (const double slide : {0.0, 10.0}) {
    Folding f;
    psc::bullet::Settings settings;
    settings.self_collision = true;
    auto plugin = psc::bullet::install(f.w.world, settings);
    f.w.run(1);  // the flat cloth is the rest shape
    fold(*f.cloth, rho);
    for (int i = 0; i < f.cloth->m_nodes.size(); ++i) {
      btSoftBody::Node& n = f.cloth->m_nodes[i];
      n.m_v = btVector3(0, btScalar(slide), n.m_x.z() > btScalar(rho) ? -0.3f : 0.0f);
    }
    const auto gap = [&] {
      double up = 0, low = 0;
      int n_up = 0, n_low = 0;
      for (int i = 0; i < f.cloth->m_nodes.size(); ++i) {
        const btVector3& x = f.cloth->m_nodes[i].m_x;
        if (x.x() > -0.8f && x.x() < -0.3f) (x.z() > btScalar(rho) ? (up += x.z(), ++n_up) : (low += x.z(), ++n_low));
      }
      return up / n_up - low / n_low;
    };
    const psc::BodyId id = *plugin.bodyId(f.cloth);
    const double radius = plugin.sensorWorld().selfRadius(id);
    double widest = 0.0;
    int contacts = 0, beyond = 0;
    f.w.run(3, [&] {
      const psc::Vec3 mean = plugin.sensorWorld().selfMeanMotion(id);
      for (int i = 0; i < f.cloth->m_scontacts.size(); ++i) {
        const btSoftBody::SContact& c = f.cloth->m_scontacts[i];
        const btVector3 d = c.m_node->m_x - c.m_node->m_q;
        const double rule = radius + 2.0 * psc::selfMotion(psc::Vec3(d.x(), d.y(), d.z()), mean);
        beyond += double(c.m_margin) > rule * (1.0 + 1e-6);
        widest = std::max(widest, double(c.m_margin));
        ++contacts;
      }
    });
    gaps.push_back(gap());
    widests.push_back(widest);
    std::printf("sliding at %.0f m/s: %d self contacts, widest margin %.4f (self radius %.4f), gap %.4f\n", slide,
                contacts, widest, radius, gaps.back());
    EXPECT_GT(contacts, 1000);
    EXPECT_EQ(beyond, 0) << "self contacts with a margin beyond the self rule's radius, sliding at " << slide;
  }
  EXPECT_LT(widests[1], 1.5 * widests[0]) << "the sliding cloth's margins are not its speed";
  EXPECT_NEAR(gaps[1], gaps[0], 0.2 * gaps[0]) << "the same physics sliding or not";
}

TEST(SelfCollision, PerBodySwitchOverridesTheSettings) {
  Folding f;
  auto plugin = psc::bullet::install(f.w.world);
  plugin.setSelfCollision(f.cloth, true);
  f.w.run(1);
  fold(*f.cloth, 0.015);
  int folded = -1;
  f.w.run(1, [&] { folded = selfContacts(*f.cloth); });
  EXPECT_GT(folded, 100);
  ASSERT_TRUE(plugin.bodyId(f.cloth));
  EXPECT_TRUE(plugin.sensorWorld().selfCollision(*plugin.bodyId(f.cloth)));
  plugin.setSelfCollision(f.cloth, false);
  f.w.run(1, [&] { folded = selfContacts(*f.cloth); });
  EXPECT_EQ(folded, 0);
}

/// Kinetic energy of the body's nodes (pinned nodes, with no inverse mass, left out).
double kineticEnergy(const btSoftBody& body) {
  double e = 0.0;
  for (int i = 0; i < body.m_nodes.size(); ++i) {
    const btSoftBody::Node& n = body.m_nodes[i];
    if (n.m_im > 0) e += 0.5 * double(n.m_v.length2()) / double(n.m_im);
  }
  return e;
}

TEST(SelfCollision, AClothLyingFlatNeitherJittersNorGainsEnergy) {
  // The exclusion rule's promise (docs/METHOD.md §6.3): the surface next to itself is not a fold.
  // A cloth dropped flat onto the ground from just above it, then left lying there for 4 s, with
  // self-collision on and off: with it on, not one self pair reaches the exact test and no self
  // contact is made, so the two runs are the same bit for bit (nothing added that could jitter),
  // and the cloth comes to rest (no energy gained while it lies there).
  std::vector<std::size_t> hashes;
  std::vector<std::vector<double>> energy;  // per run, the most kinetic energy in each second
  for (const bool on : {false, true}) {
    psc_test::SoftWorld w;  // gravity -10 along y
    w.addBox({3, 0.5, 3}, 0, {0, -0.5, 0});
    psc::TriMesh patch = psc::makePatch(2.0, 1.0, 41, 21);  // in the xy plane
    for (psc::Vec3& p : patch.vertices) p = psc::Vec3(p.x(), 0.05, p.y());  // turned to lie on the ground
    psc_test::SoftParams params;
    params.margin = 0.02;
    params.shape_matching = 0;
    btSoftBody* cloth = w.addSoft(patch, params);
    psc::bullet::Settings settings;
    settings.self_collision = on;
    auto plugin = psc::bullet::install(w.world, settings);
    std::size_t self_tests = 0, self_made = 0;
    std::vector<double> most(4, 0.0);
    for (int step = 0; step < 240; ++step) {
      w.run(1, [&] {
        self_tests += plugin.stats().self_exact_tests;
        self_made += static_cast<std::size_t>(selfContacts(*cloth));
      });
      const double e = kineticEnergy(*cloth);  // after the step's solve
      most[static_cast<std::size_t>(step / 60)] = std::max(most[static_cast<std::size_t>(step / 60)], e);
    }
    std::printf("self-collision %s: %zu self exact tests, %zu self contacts, kinetic energy at most %.3g / %.3g / "
                "%.3g / %.3g J in seconds 1-4\n", on ? "on" : "off", self_tests, self_made, most[0], most[1], most[2],
                most[3]);
    EXPECT_EQ(self_tests, 0u);
    EXPECT_EQ(self_made, 0u);
    for (std::size_t k = 1; k < most.size(); ++k)
      EXPECT_LE(most[k], most[k - 1]) << "the cloth gained energy lying on the ground, second " << k + 1;
    EXPECT_LT(most.back(), 1e-3 * most.front()) << "the cloth does not come to rest";
    if (on) {
      EXPECT_TRUE(plugin.sensorWorld().selfCollision(*plugin.bodyId(cloth))) << "the cloth is collided with itself";
    }
    hashes.push_back(psc_test::positionHash(w.world.getSoftBodyArray()));
    energy.push_back(most);
  }
  EXPECT_EQ(hashes[0], hashes[1]) << "switching self-collision on moved the flat cloth";
  EXPECT_EQ(energy[0], energy[1]);
}

}  // namespace
