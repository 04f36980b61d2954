// psc::bullet::alignLargeBulletBlocks: Bullet's arrays on cache lines, blocks freed by either
// allocator, and a simulation that does not change by a bit.
#include "psc/bullet/bullet.h"
#include "soft_world.h"

#include <BulletSoftBody/btSoftBody.h>
#include <LinearMath/btAlignedAllocator.h>
#include <gtest/gtest.h>

#include <cstdint>
#include <vector>

namespace {

std::uintptr_t lineOffset(const void* p) { return reinterpret_cast<std::uintptr_t>(p) % 64; }

/// Restores Bullet's default allocator whatever a test does.
struct DefaultAllocatorAfter {
  ~DefaultAllocatorAfter() { psc::bullet::restoreBulletBlockAlignment(); }
};

TEST(BlockAlignment, LargeBlocksStartOnACacheLineSmallOnesKeepTheirAlignment) {
  DefaultAllocatorAfter restore;
  psc::bullet::alignLargeBulletBlocks();
  EXPECT_TRUE(psc::bullet::largeBulletBlocksAligned());
  for (std::size_t size : {psc::bullet::kLineAlignedBlockBytes, std::size_t(100000), std::size_t(12800000)}) {
    auto* p = static_cast<unsigned char*>(btAlignedAlloc(size, 16));
    ASSERT_NE(p, nullptr);
    EXPECT_EQ(lineOffset(p), 0u) << size << " bytes";
    // Bullet's default zeroes its blocks; so does this one.
    std::size_t nonzero = 0;
    for (std::size_t i = 0; i < size; ++i) nonzero += p[i] != 0;
    EXPECT_EQ(nonzero, 0u) << size << " bytes";
    btAlignedFree(p);
  }
  for (std::size_t size : {std::size_t(1), std::size_t(24), std::size_t(4095)}) {
    void* p = btAlignedAlloc(size, 16);
    ASSERT_NE(p, nullptr);
    EXPECT_EQ(reinterpret_cast<std::uintptr_t>(p) % 16, 0u) << size << " bytes";
    btAlignedFree(p);
  }
  // An alignment above 64 is kept.
  void* p = btAlignedAlloc(8192, 128);
  EXPECT_EQ(reinterpret_cast<std::uintptr_t>(p) % 128, 0u);
  btAlignedFree(p);
}

TEST(BlockAlignment, BlocksOfEitherAllocatorAreFreedByTheOther) {
  // Under AddressSanitizer a free of the wrong address fails this test; without it, the blocks'
  // contents are checked across the switch.
  DefaultAllocatorAfter restore;
  psc::bullet::restoreBulletBlockAlignment();
  EXPECT_FALSE(psc::bullet::largeBulletBlocksAligned());
  btAlignedObjectArray<btVector3> before;
  before.resize(5000, btVector3(1, 2, 3));
  psc::bullet::alignLargeBulletBlocks();
  btAlignedObjectArray<btVector3> during;
  during.resize(5000, btVector3(4, 5, 6));
  EXPECT_EQ(lineOffset(&during[0]), 0u);
  before.resize(20000, btVector3(7, 8, 9));  // a block of the default freed by this allocator
  EXPECT_EQ(lineOffset(&before[0]), 0u);
  EXPECT_EQ(before[4999], btVector3(1, 2, 3));
  EXPECT_EQ(before[19999], btVector3(7, 8, 9));
  psc::bullet::restoreBulletBlockAlignment();
  during.resize(20000, btVector3(0, 0, 1));  // a block of this allocator freed by the default
  EXPECT_EQ(during[4999], btVector3(4, 5, 6));
  before.clear();
  during.clear();
}

TEST(BlockAlignment, NodesOfABodyCreatedAfterItHaveTheirPositionsOnOneLine) {
  // With double-precision Bullet m_x and m_q are 32 bytes each from offset 16 of the node: 64
  // bytes that no alignment of the array puts on one line.
  if (sizeof(btScalar) != sizeof(float)) GTEST_SKIP() << "m_x and m_q span two lines in double-precision Bullet";
  DefaultAllocatorAfter restore;
  psc::bullet::alignLargeBulletBlocks();
  psc_test::SoftWorld w;
  btSoftBody* ball = w.addSoft(psc::makeSphere(1.0, 2000));
  ASSERT_GE(ball->m_nodes.size(), 2000);
  for (int i = 0; i < ball->m_nodes.size(); ++i) {
    const btSoftBody::Node& n = ball->m_nodes[i];
    const auto line = [](const void* p) { return reinterpret_cast<std::uintptr_t>(p) / 64; };
    // m_x's first byte and m_q's last byte on the same line.
    ASSERT_EQ(line(n.m_x.m_floats), line(reinterpret_cast<const char*>(n.m_q.m_floats) + sizeof(btVector3) - 1))
        << "node " << i;
  }
}

TEST(BlockAlignment, TheSimulationIsTheSameBitForBit) {
  DefaultAllocatorAfter restore;
  const auto trace = [](bool aligned) {
    if (aligned) psc::bullet::alignLargeBulletBlocks();
    else psc::bullet::restoreBulletBlockAlignment();
    psc_test::SoftWorld w(psc_test::sceneGravity(psc_test::Scene::Pile));
    psc_test::buildScene(psc_test::Scene::Pile, w);
    auto plugin = psc::bullet::install(w.world);
    std::vector<std::size_t> out;
    for (int s = 0; s < 60; ++s) {
      w.step();
      out.push_back(psc_test::positionHash(w.world.getSoftBodyArray()));
      out.push_back(plugin.stats().contacts);
      out.push_back(plugin.stats().exact_tests);
    }
    return out;
  };
  const std::vector<std::size_t> plain = trace(false), aligned = trace(true);
  std::size_t contacts = 0;
  for (std::size_t s = 1; s < plain.size(); s += 3) contacts += plain[s];
  EXPECT_GT(contacts, 1000u) << "the bodies must touch";
  EXPECT_EQ(plain, aligned);
}

}  // namespace
