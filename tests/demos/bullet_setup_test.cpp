// The instruments inside Bullet change nothing Bullet does: the fast VF_SS setup builds Bullet's
// own trees, the face-refit split leaves every node position bit-identical, and the zone timer and
// the exact-test count see the soft-soft work.
#include "bullet_probe.h"
#include "bullet_scene.h"
#include "bullet_vf_setup.h"
#include "psc/error.h"

#include <gtest/gtest.h>

namespace psc::demo {
namespace {

SoftBodySpec specOf(const char* name, TriMesh mesh, int bending) {
  SoftBodySpec s;
  s.name = name;
  s.mesh = std::move(mesh);
  s.bending_distance = bending;
  return s;
}

/// What btSoftBody::predictMotion does on its first call for a VF_SS body (Bullet 3.24).
void bulletOwnSetup(btSoftBody& b) {
  b.m_bUpdateRtCst = false;
  b.updateConstants();
  b.m_fdbvt.clear();
  b.initializeFaceTree();
}

TEST(BulletSetup, FastSetupBuildsBulletsOwnTrees) {
  const int vfss = btSoftBody::fCollision::SDF_RS | btSoftBody::fCollision::VF_SS;
  const SoftBodySpec specs[] = {
      specOf("sphere", makeSphere(1.0, 300), 0),
      specOf("torus", makeTorus(1.0, 0.3, 400), 0),
      specOf("u_shape", makeUShape(1.2, 1.0, 0.2, 300), 0),
      specOf("patch_with_bending_links", makePatch(2.0, 2.0, 14, 14), 2),
      specOf("fork", makeFork(2.0, 0.2, 300), 0),
  };
  for (const SoftBodySpec& spec : specs) {
    btSoftBodyWorldInfo info;
    info.m_sparsesdf.Initialize();
    btSoftBody* fast = createSoftBody(info, spec, vfss, 4, true);
    btSoftBody* own = createSoftBody(info, spec, vfss, 4, false);
    bulletOwnSetup(*own);
    EXPECT_FALSE(fast->m_bUpdateRtCst) << spec.name;
    EXPECT_TRUE(sameTree(fast->m_fdbvt.m_root, own->m_fdbvt.m_root, *fast, *own, true)) << spec.name << ": face tree";
    EXPECT_TRUE(sameTree(fast->m_ndbvt.m_root, own->m_ndbvt.m_root, *fast, *own, false)) << spec.name << ": node tree";
    delete fast;
    delete own;
  }
}

TEST(BulletSetup, BendingLinksEqualBulletsOwn) {
  for (const TriMesh& mesh : {makeSphere(1.0, 200), makePatch(2.0, 2.0, 9, 11), makeTorus(1.0, 0.3, 150)}) {
    SoftBodySpec spec = specOf("body", mesh, 0);
    btSoftBodyWorldInfo info;
    btSoftBody* ours = createSoftBody(info, spec, btSoftBody::fCollision::SDF_RS, 4);
    btSoftBody* own = createSoftBody(info, spec, btSoftBody::fCollision::SDF_RS, 4);
    const int added = appendBendingLinks2(*ours, ours->appendMaterial());
    EXPECT_EQ(added, own->generateBendingConstraints(2, own->appendMaterial()));
    ASSERT_EQ(ours->m_links.size(), own->m_links.size());
    for (int i = 0; i < ours->m_links.size(); ++i) {
      for (int k = 0; k < 2; ++k)
        ASSERT_EQ(ours->m_links[i].m_n[k] - &ours->m_nodes[0], own->m_links[i].m_n[k] - &own->m_nodes[0]) << "link " << i;
      ASSERT_EQ(ours->m_links[i].m_bbending, own->m_links[i].m_bbending) << "link " << i;
    }
    EXPECT_GT(added, 0);
    delete ours;
    delete own;
  }
}

TEST(BulletSetup, BodyInSeveralPiecesIsAnErrorNotAHang) {
  TriMesh two = makeSphere(1.0, 100);
  TriMesh other = makeSphere(1.0, 100).translate({3, 0, 0});
  const auto offset = static_cast<Index>(two.vertices.size());
  for (const Vec3& v : other.vertices) two.vertices.push_back(v);
  for (Triangle t : other.triangles) two.triangles.push_back({t[0] + offset, t[1] + offset, t[2] + offset});
  btSoftBodyWorldInfo info;
  try {
    delete createSoftBody(info, specOf("two_balls", two, 0), btSoftBody::fCollision::SDF_RS | btSoftBody::fCollision::VF_SS, 4);
    FAIL() << "expected psc::Error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("two_balls"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("several unconnected pieces"), std::string::npos) << e.what();
  }
}

std::vector<btVector3> positionsAfter(const Scene& scene, std::size_t steps, bool fast, bool split) {
  WorldOptions o;
  o.fast_vf_setup = fast;
  o.split_face_refit = split;
  SceneWorld sw(scene, o);
  for (std::size_t s = 0; s < steps; ++s) sw.step();
  std::vector<btVector3> out;
  for (btSoftBody* b : sw.softBodies())
    for (int i = 0; i < b->m_nodes.size(); ++i) out.push_back(b->m_nodes[i].m_x);
  return out;
}

TEST(BulletSetup, InstrumentsLeaveBulletsSimulationBitIdentical) {
  for (const char* name : {"head_on", "cloth_ball"}) {
    SceneParams p;
    p.resolution = 250;
    const Scene scene = makeScene(name, p);
    const auto reference = positionsAfter(scene, 40, false, false);  // Bullet as shipped
    for (bool fast : {false, true})
      for (bool split : {false, true}) {
        const auto got = positionsAfter(scene, 40, fast, split);
        ASSERT_EQ(got.size(), reference.size());
        std::size_t differ = 0;
        for (std::size_t i = 0; i < got.size(); ++i) differ += !(got[i] == reference[i]);
        EXPECT_EQ(differ, 0u) << name << " fast setup " << fast << ", split refit " << split;
      }
  }
}

TEST(BulletProbe, ZoneTimerAndExactTestsSeeTheSoftSoftWork) {
  SceneParams p;
  p.resolution = 300;
  const Scene scene = makeScene("head_on", p);
  SceneWorld sw(scene);
  ZoneTimer zone("Deformable Collision");
  std::size_t exact = 0;
  sw.world().before_collision = [&] { zone.arm(true); };
  sw.world().after_collision = [&] {
    zone.arm(false);
    exact += countVFExactTests(sw.world());
  };
  double ms = 0;
  std::size_t entries = 0;
  for (int s = 0; s < 25; ++s) {
    sw.step();
    ms += zone.takeMs();
    entries += zone.takeCount();
  }
  EXPECT_GT(entries, 0u);
  EXPECT_GT(ms, 0.0);
  EXPECT_GT(exact, 0u);
  EXPECT_GT(bulletMidphaseBytes(*sw.softBodies()[0]), 2 * sizeof(btDbvtNode) * 300);
  // Disarmed: the self-collision pass after the solver fires the same zone and must not count.
  sw.world().before_collision = nullptr;
  sw.step();
  EXPECT_EQ(zone.takeCount(), 0u);
}

}  // namespace
}  // namespace psc::demo
