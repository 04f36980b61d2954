// The plugin under a dispatcher that collides soft-soft pairs from two threads at once, as Bullet's
// btCollisionDispatcherMt does in a BT_THREADSAFE build. Debian's Bullet 3.24 is built without
// BT_THREADSAFE (its btParallelFor runs the loop on the calling thread), so the test brings its own
// two-thread dispatcher. The plugin's lock must make the result identical to a one-thread run;
// the ThreadSanitizer stage of .ci/run (PSC_TSAN) runs these tests to catch unlocked accesses.
#include "contact_check.h"
#include "psc/bullet/bullet.h"
#include "soft_world.h"

#include <BulletCollision/BroadphaseCollision/btCollisionAlgorithm.h>
#include <BulletCollision/BroadphaseCollision/btOverlappingPairCache.h>
#include <BulletCollision/CollisionDispatch/btCollisionObjectWrapper.h>
#include <BulletCollision/CollisionDispatch/btManifoldResult.h>

#include <gtest/gtest.h>

#include <atomic>
#include <memory>
#include <thread>
#include <utility>
#include <vector>

namespace {

/// Bullet's defaultNearCallback, split in two: algorithms are found (and pool-allocated) on the
/// calling thread, then the soft-soft pairs are processed half on a second thread, half on this
/// one. Other pairs stay on this thread (Bullet's own algorithms are not thread-safe in this build).
class TwoThreadDispatcher : public btCollisionDispatcher {
 public:
  using btCollisionDispatcher::btCollisionDispatcher;

  void dispatchAllCollisionPairs(btOverlappingPairCache* cache, const btDispatcherInfo& info, btDispatcher*) override {
    btBroadphasePairArray& pairs = cache->getOverlappingPairArray();
    std::vector<btBroadphasePair*> soft_pairs;
    for (int i = 0; i < pairs.size(); ++i) {
      btBroadphasePair& pair = pairs[i];
      const auto* a = static_cast<const btCollisionObject*>(pair.m_pProxy0->m_clientObject);
      const auto* b = static_cast<const btCollisionObject*>(pair.m_pProxy1->m_clientObject);
      if (!needsCollision(a, b)) continue;
      const btCollisionObjectWrapper wa(nullptr, a->getCollisionShape(), a, a->getWorldTransform(), -1, -1);
      const btCollisionObjectWrapper wb(nullptr, b->getCollisionShape(), b, b->getWorldTransform(), -1, -1);
      if (pair.m_algorithm == nullptr) pair.m_algorithm = findAlgorithm(&wa, &wb, nullptr, BT_CONTACT_POINT_ALGORITHMS);
      if (pair.m_algorithm == nullptr) continue;
      if (btSoftBody::upcast(a) != nullptr && btSoftBody::upcast(b) != nullptr) {
        soft_pairs.push_back(&pair);
      } else {
        process(pair, info);
      }
    }
    std::atomic<int> second_thread_pairs{0};
    std::thread second([&] {
      for (std::size_t i = 1; i < soft_pairs.size(); i += 2) {
        process(*soft_pairs[i], info);
        ++second_thread_pairs;
      }
    });
    for (std::size_t i = 0; i < soft_pairs.size(); i += 2) process(*soft_pairs[i], info);
    second.join();
    if (second_thread_pairs > 0) ++steps_on_two_threads;
  }

  int steps_on_two_threads = 0;  ///< dispatches in which both threads collided soft-soft pairs

 private:
  static void process(btBroadphasePair& pair, const btDispatcherInfo& info) {
    const auto* a = static_cast<const btCollisionObject*>(pair.m_pProxy0->m_clientObject);
    const auto* b = static_cast<const btCollisionObject*>(pair.m_pProxy1->m_clientObject);
    const btCollisionObjectWrapper wa(nullptr, a->getCollisionShape(), a, a->getWorldTransform(), -1, -1);
    const btCollisionObjectWrapper wb(nullptr, b->getCollisionShape(), b, b->getWorldTransform(), -1, -1);
    btManifoldResult result(&wa, &wb);
    pair.m_algorithm->processCollision(&wa, &wb, info, &result);
  }
};

/// Three head-on pairs of soft spheres, 4 m apart: every body touches one other body only, so its
/// contacts come from one pair and their order in m_scontacts (which the soft solver depends on)
/// does not depend on which thread collided which pair.
void threePairs(psc_test::SoftWorld& w) {
  for (int k = 0; k < 3; ++k) {
    const double z = 4.0 * k;
    w.addSoft(psc::makeSphere(0.5, 200).translate({-0.6, 0, z}), {}, {3, 0, 0});
    w.addSoft(psc::makeSphere(0.5, 200).translate({0.6, 0.05 * k, z}), {}, {-3, 0, 0});
  }
}

struct Trace {
  std::vector<std::size_t> hashes;    ///< node positions after each step
  std::vector<std::size_t> contacts;  ///< plugin contacts of each step
  std::size_t duplicates = 0;
  int steps_on_two_threads = 0;
};

/// With `two_threads`, a factory of TwoThreadDispatcher (the one made is kept in `threaded`);
/// otherwise none (Bullet's dispatcher).
psc_test::DispatcherFactory dispatcherFor(bool two_threads, TwoThreadDispatcher*& threaded) {
  if (!two_threads) return {};
  return [&threaded](btCollisionConfiguration* config) {
    auto dispatcher = std::make_unique<TwoThreadDispatcher>(config);
    threaded = dispatcher.get();
    return dispatcher;
  };
}

Trace run(bool two_threads, int steps) {
  TwoThreadDispatcher* threaded = nullptr;
  psc_test::SoftWorld w(0.0, dispatcherFor(two_threads, threaded));
  threePairs(w);
  auto plugin = psc::bullet::install(w.world);
  Trace trace;
  for (int s = 0; s < steps; ++s) {
    w.run(1, [&] { trace.duplicates += psc_test::auditContacts(w.world.getSoftBodyArray()).duplicates; });
    EXPECT_TRUE(plugin.stats().error.empty()) << plugin.stats().error;
    EXPECT_EQ(plugin.stats().sensor_steps, std::uint64_t(s + 1)) << "one sensor step per simulation step";
    trace.hashes.push_back(psc_test::positionHash(w.world.getSoftBodyArray()));
    trace.contacts.push_back(plugin.stats().contacts);
  }
  if (threaded != nullptr) trace.steps_on_two_threads = threaded->steps_on_two_threads;
  return trace;
}

TEST(Threads, TwoThreadDispatchMatchesOneThreadBitForBit) {
  constexpr int kSteps = 30;
  const Trace one = run(false, kSteps);
  const Trace two = run(true, kSteps);
  std::size_t contacts = 0;
  for (std::size_t c : one.contacts) contacts += c;
  EXPECT_GT(contacts, 1000u) << "the pairs must touch";
  // The three pairs overlap in the broadphase during the contact steps: both threads collide.
  EXPECT_GT(two.steps_on_two_threads, 5);
  EXPECT_EQ(one.duplicates, 0u);
  EXPECT_EQ(two.duplicates, 0u) << "each (node, face) at most once a step, whichever thread asks";
  EXPECT_EQ(two.contacts, one.contacts);
  EXPECT_EQ(two.hashes, one.hashes);
}

// A body that meets a participating body and one left to Bullet (setEnabled false) at once: the
// two pairs, collided on two threads, both write the middle body's m_scontacts (the plugin's pair
// and its room for them each step, Bullet's own test through the previous algorithm). The lock
// must cover both; the ThreadSanitizer stage reports it if not. Which pair pushes first decides
// the contacts' order, so only what does not depend on it is compared with a one-thread run.
TEST(Threads, APluginPairAndABulletPairOnOneBodyFromTwoThreads) {
  // The middle body's contacts each step; returns the steps in which both threads collided.
  const auto runMixed = [](bool two_threads, std::vector<std::size_t>& contacts) {
    TwoThreadDispatcher* threaded = nullptr;
    psc_test::SoftWorld w(0.0, dispatcherFor(two_threads, threaded));
    btSoftBody* middle = w.addSoft(psc::makeSphere(0.5, 200));
    w.addSoft(psc::makeSphere(0.5, 200).translate({1.2, 0, 0}), {}, {-3, 0, 0});
    btSoftBody* bullets = w.addSoft(psc::makeSphere(0.5, 200).translate({-1.2, 0.05, 0}), {}, {3, 0, 0});
    auto plugin = psc::bullet::install(w.world);
    plugin.setEnabled(bullets, false);
    for (int s = 0; s < 12; ++s) {
      std::size_t made = 0;
      w.run(1, [&] { made = static_cast<std::size_t>(middle->m_scontacts.size()); });
      EXPECT_TRUE(plugin.stats().error.empty()) << plugin.stats().error;
      contacts.push_back(made);
    }
    EXPECT_GT(plugin.stats().fallback_pairs, 0u) << "the pair with the opted-out body is Bullet's";
    EXPECT_GT(plugin.stats().contacts, 0u) << "the pair of participating bodies is the plugin's";
    return threaded != nullptr ? threaded->steps_on_two_threads : 0;
  };
  std::vector<std::size_t> one, two;
  runMixed(false, one);
  const int two_on_two = runMixed(true, two);
  EXPECT_GT(two_on_two, 3) << "both threads must collide a pair in some steps";
  std::size_t touching = 0;
  for (std::size_t c : one) touching += c > 0;
  EXPECT_GT(touching, 3u) << "the middle body must meet the others";
  // The first step with contacts is the same in both: the positions before it do not depend on
  // the order of contacts (there were none).
  const auto first = [](const std::vector<std::size_t>& c) {
    for (std::size_t i = 0; i < c.size(); ++i)
      if (c[i] > 0) return std::make_pair(i, c[i]);
    return std::make_pair(c.size(), std::size_t{0});
  };
  EXPECT_EQ(first(two), first(one));
}

}  // namespace
