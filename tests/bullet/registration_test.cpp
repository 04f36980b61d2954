// The plugin's algorithm is the one Bullet calls for soft-soft pairs, whenever it was installed,
// and uninstalling gives Bullet's (or whatever was registered before) back.
#include "psc/bullet/bullet.h"
#include "psc/error.h"
#include "soft_world.h"

#include <BulletSoftBody/btSoftSoftCollisionAlgorithm.h>
#include <gtest/gtest.h>

namespace {

using psc_test::SoftWorld;

// Same standard technique as the plugin's: read the dispatcher's table through a derived class.
struct Table : btCollisionDispatcher {
  static btCollisionAlgorithmCreateFunc* softSoft(const btCollisionDispatcher& d) {
    return (d.*(&Table::m_doubleDispatchContactPoints))[SOFTBODY_SHAPE_PROXYTYPE][SOFTBODY_SHAPE_PROXYTYPE];
  }
};

struct Actions : btDiscreteDynamicsWorld {
  static int count(const btDiscreteDynamicsWorld& w) { return (w.*(&Actions::m_actions)).size(); }
};

/// The algorithms cached by the world's soft-soft broadphase pairs.
std::vector<btCollisionAlgorithm*> softSoftAlgorithms(SoftWorld& w) {
  std::vector<btCollisionAlgorithm*> algorithms;
  btBroadphasePairArray& pairs = w.broadphase.getOverlappingPairCache()->getOverlappingPairArray();
  for (int i = 0; i < pairs.size(); ++i) {
    const auto* a = static_cast<btCollisionObject*>(pairs[i].m_pProxy0->m_clientObject);
    const auto* b = static_cast<btCollisionObject*>(pairs[i].m_pProxy1->m_clientObject);
    if (btSoftBody::upcast(a) && btSoftBody::upcast(b)) algorithms.push_back(pairs[i].m_algorithm);
  }
  return algorithms;
}

void addTouchingBalls(SoftWorld& w) {
  w.addSoft(psc::makeSphere(0.5, 200).translate({-0.52, 0, 0}), {}, {1, 0, 0});
  w.addSoft(psc::makeSphere(0.5, 200).translate({0.52, 0, 0}), {}, {-1, 0, 0});
}

bool isBullets(const btCollisionAlgorithm* algorithm) {
  return dynamic_cast<const btSoftSoftCollisionAlgorithm*>(algorithm) != nullptr;
}

TEST(Registration, InstalledBeforeBodiesExist) {
  SoftWorld w(0);
  auto plugin = psc::bullet::install(w.world);
  addTouchingBalls(w);
  w.run(3);
  const auto algorithms = softSoftAlgorithms(w);
  ASSERT_EQ(algorithms.size(), 1u);
  EXPECT_TRUE(plugin.owns(algorithms[0]));
  EXPECT_FALSE(isBullets(algorithms[0]));
  EXPECT_EQ(plugin.stats().body_pairs, 1u);
  EXPECT_GT(plugin.stats().contacts, 0u);
}

/// A near callback that refuses every soft–soft pair, as a program filtering pairs would.
void refuseSoftPairs(btBroadphasePair& pair, btCollisionDispatcher& dispatcher, const btDispatcherInfo& info) {
  const auto* a = static_cast<btCollisionObject*>(pair.m_pProxy0->m_clientObject);
  const auto* b = static_cast<btCollisionObject*>(pair.m_pProxy1->m_clientObject);
  if (btSoftBody::upcast(a) && btSoftBody::upcast(b)) return;
  btCollisionDispatcher::defaultNearCallback(pair, dispatcher, info);
}

TEST(Registration, APairTheProgramsNearCallbackRefusesStaysRefused) {
  // The plugin collides the body pairs whose candidates the broadphase does not have
  // (Settings::beyond_broadphase), after Bullet's dispatch. A pair the broadphase has but the
  // program's near callback refused was not collided either, and must stay so: it did get
  // contacts (a review's finding). Bullet's own path makes none, and neither does the plugin.
  for (const bool plugin_on : {false, true}) {
    SoftWorld w(0);
    w.dispatcher.setNearCallback(refuseSoftPairs);
    psc::bullet::Plugin plugin;
    if (plugin_on) plugin = psc::bullet::install(w.world);
    addTouchingBalls(w);
    int contacts = -1;
    w.run(2, [&] {
      contacts = 0;
      for (int i = 0; i < w.world.getSoftBodyArray().size(); ++i) contacts += w.world.getSoftBodyArray()[i]->m_scontacts.size();
    });
    EXPECT_EQ(contacts, 0) << (plugin_on ? "plugin" : "Bullet");
    if (plugin_on) {
      EXPECT_EQ(plugin.stats().beyond_broadphase_pairs, 0u);
      EXPECT_GT(plugin.stats().candidate_pairs, 0u) << "the sensors did find the touching pair";
    }
  }
}

TEST(Registration, InstalledAfterPairsCachedBulletsAlgorithm) {
  SoftWorld w(0);
  addTouchingBalls(w);
  w.run(2);
  auto before = softSoftAlgorithms(w);
  ASSERT_EQ(before.size(), 1u);
  ASSERT_TRUE(isBullets(before[0]));
  auto plugin = psc::bullet::install(w.world);
  w.run(1);
  const auto after = softSoftAlgorithms(w);
  ASSERT_EQ(after.size(), 1u);
  EXPECT_TRUE(plugin.owns(after[0]));
  EXPECT_EQ(plugin.stats().body_pairs, 1u);
}

TEST(Registration, UninstallRestoresBulletsAlgorithm) {
  SoftWorld w(0);
  btCollisionAlgorithmCreateFunc* bullets = Table::softSoft(w.dispatcher);
  ASSERT_EQ(bullets, w.config.getCollisionAlgorithmCreateFunc(SOFTBODY_SHAPE_PROXYTYPE, SOFTBODY_SHAPE_PROXYTYPE));
  addTouchingBalls(w);
  {
    auto plugin = psc::bullet::install(w.world);
    EXPECT_NE(Table::softSoft(w.dispatcher), bullets);
    w.run(2);
    ASSERT_TRUE(plugin.owns(softSoftAlgorithms(w).at(0)));
  }  // destroyed: uninstalled
  EXPECT_EQ(Table::softSoft(w.dispatcher), bullets);
  EXPECT_EQ(Actions::count(w.world), 0);
  w.run(1);
  const auto after = softSoftAlgorithms(w);
  ASSERT_EQ(after.size(), 1u);
  EXPECT_TRUE(isBullets(after[0]));
  // Bullet's own path still produces contacts after the plugin is gone.
  int contacts = 0;
  for (int i = 0; i < w.world.getSoftBodyArray().size(); ++i) contacts += w.world.getSoftBodyArray()[i]->m_scontacts.size();
  w.run(1, [&] {
    contacts = 0;
    for (int i = 0; i < w.world.getSoftBodyArray().size(); ++i) contacts += w.world.getSoftBodyArray()[i]->m_scontacts.size();
  });
  EXPECT_GT(contacts, 0);
}

TEST(Registration, ExplicitUninstallAndMoveAreSafe) {
  SoftWorld w(0);
  addTouchingBalls(w);
  auto plugin = psc::bullet::install(w.world);
  w.run(1);
  psc::bullet::Plugin moved = std::move(plugin);
  EXPECT_FALSE(plugin.installed());
  EXPECT_TRUE(moved.installed());
  w.run(1);
  EXPECT_EQ(moved.stats().body_pairs, 1u);
  moved.uninstall();
  moved.uninstall();
  EXPECT_FALSE(moved.installed());
  w.run(1);
  EXPECT_TRUE(isBullets(softSoftAlgorithms(w).at(0)));
}

/// A user's own create func registered before install() is what pairs the plugin declines go to,
/// and what uninstall() restores.
struct CountingCreateFunc : btSoftSoftCollisionAlgorithm::CreateFunc {
  btCollisionAlgorithm* CreateCollisionAlgorithm(btCollisionAlgorithmConstructionInfo& info,
                                                 const btCollisionObjectWrapper* a,
                                                 const btCollisionObjectWrapper* b) override {
    ++created;
    return btSoftSoftCollisionAlgorithm::CreateFunc::CreateCollisionAlgorithm(info, a, b);
  }
  int created = 0;
};

TEST(Registration, ChainsToAndRestoresAPreviousCustomAlgorithm) {
  SoftWorld w(0);
  CountingCreateFunc custom;
  w.dispatcher.registerCollisionCreateFunc(SOFTBODY_SHAPE_PROXYTYPE, SOFTBODY_SHAPE_PROXYTYPE, &custom);
  addTouchingBalls(w);
  {
    auto plugin = psc::bullet::install(w.world);
    plugin.setEnabled(w.world.getSoftBodyArray()[0], false);  // the pair is not the sensors'
    w.run(2);
    EXPECT_EQ(custom.created, 1);
    EXPECT_EQ(plugin.stats().fallback_pairs, 1u);
    EXPECT_EQ(plugin.stats().body_pairs, 0u);
  }
  EXPECT_EQ(Table::softSoft(w.dispatcher), &custom);
  w.dispatcher.registerCollisionCreateFunc(SOFTBODY_SHAPE_PROXYTYPE, SOFTBODY_SHAPE_PROXYTYPE,
                                           w.config.getCollisionAlgorithmCreateFunc(SOFTBODY_SHAPE_PROXYTYPE,
                                                                                    SOFTBODY_SHAPE_PROXYTYPE));
  btBroadphasePairArray& pairs = w.broadphase.getOverlappingPairCache()->getOverlappingPairArray();
  for (int i = 0; i < pairs.size(); ++i) w.broadphase.getOverlappingPairCache()->cleanOverlappingPair(pairs[i], &w.dispatcher);
}

TEST(Registration, SecondInstallOnTheSameWorldIsRefused) {
  SoftWorld w(0);
  auto plugin = psc::bullet::install(w.world);
  try {
    auto second = psc::bullet::install(w.world);
    FAIL() << "a second install was accepted";
  } catch (const psc::Error& e) {
    EXPECT_EQ(e.code(), psc::ErrorCode::InvalidArgument);
    EXPECT_NE(std::string(e.what()).find("already installed"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(plugin.installed());
}

TEST(Registration, InvalidSettingsAreRejectedBeforeAnythingIsRegistered) {
  SoftWorld w(0);
  btCollisionAlgorithmCreateFunc* bullets = Table::softSoft(w.dispatcher);
  psc::bullet::Settings settings;
  settings.sensors.max_rounds = 0;
  EXPECT_THROW(psc::bullet::install(w.world, settings), psc::Error);
  EXPECT_EQ(Table::softSoft(w.dispatcher), bullets);
  EXPECT_EQ(Actions::count(w.world), 0);
}

}  // namespace
