#include "psc/error.h"
#include "psc/mesh.h"
#include "psc/partition.h"
#include "psc/shapes.h"

#include "core/test_util.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <functional>
#include <random>
#include <set>
#include <string>

namespace psc {
namespace {

using Feature = Eigen::Matrix<double, 6, 1>;

TriMesh jittered(TriMesh m, unsigned seed, double amount) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-amount, amount);
  for (Vec3& v : m.vertices) v += Vec3(u(rng), u(rng), u(rng));
  return m;
}

TriMesh merged(const TriMesh& a, const TriMesh& b) {
  TriMesh m = a;
  const Index offset = static_cast<Index>(a.vertices.size());
  m.vertices.insert(m.vertices.end(), b.vertices.begin(), b.vertices.end());
  for (Triangle t : b.triangles) m.triangles.push_back({t[0] + offset, t[1] + offset, t[2] + offset});
  return m;
}

Partition run(const TriMesh& m, std::size_t count, const PartitionSettings& s = {}) {
  const MeshTopology topology(m.triangles, m.vertices.size());
  return partitionLBG(topology, PositionView::of(m.vertices), count, s);
}

// Invariants every partition must meet, whatever the mesh.
void expectValidPartition(const TriMesh& m, const Partition& p, std::size_t count) {
  ASSERT_EQ(p.regionCount(), count);
  ASSERT_EQ(p.code_vectors.size(), count);
  ASSERT_EQ(p.region_of.size(), m.vertices.size());
  std::vector<bool> in_triangle(m.vertices.size(), false);
  for (const Triangle& t : m.triangles)
    for (Index v : t) in_triangle[v] = true;
  std::vector<std::size_t> size(count, 0);
  for (std::size_t v = 0; v < m.vertices.size(); ++v) {
    ASSERT_LT(p.region_of[v], count) << "vertex " << v;
    if (in_triangle[v]) ++size[p.region_of[v]];
  }
  for (std::size_t r = 0; r < count; ++r) {
    EXPECT_GT(size[r], 0u) << "region " << r << " is empty";
    ASSERT_LT(p.seed_vertex[r], m.vertices.size());
    EXPECT_EQ(p.region_of[p.seed_vertex[r]], r);
    EXPECT_TRUE(in_triangle[p.seed_vertex[r]]) << "seed of region " << r << " cannot hop";
  }
}

// ---------------------------------------------------------------------------------------------
// LBG itself, with connectivity repair off so that Lloyd's fixed point is what comes out.

TEST(Lbg, FixedPointMatchesBruteForce) {
  PartitionSettings s;
  s.epsilon = 1e-12;
  s.max_lloyd_iterations = 10000;
  s.connect_regions = false;
  std::size_t runs = 0, near_ties = 0;
  for (unsigned seed = 1; seed <= 3; ++seed) {
    const TriMesh m = jittered(makeSphere(1.0, 700), seed, 0.08);
    const MeshTopology topology(m.triangles, m.vertices.size());
    for (std::size_t count : {2u, 5u, 8u, 13u}) {
      for (SplitRule rule : {SplitRule::Principal, SplitRule::Thesis}) {
        SCOPED_TRACE("seed " + std::to_string(seed) + " count " + std::to_string(count) +
                     (rule == SplitRule::Thesis ? " thesis" : " principal"));
        s.split = rule;
        // The thesis rule needs a mean away from the origin (§5.1.2, Fig. 5-3b).
        TriMesh shifted = m;
        if (rule == SplitRule::Thesis) shifted.translate(Vec3(2.0, -1.0, 0.5));
        const PositionView sv = PositionView::of(shifted.vertices);
        const std::vector<Feature> fs = partitionFeatures(topology, sv, s);
        const Partition p = partitionLBG(topology, sv, count, s);
        expectValidPartition(shifted, p, count);
        EXPECT_FALSE(p.hit_iteration_cap);
        EXPECT_EQ(p.failed_splits, 0u);
        // Every vertex with its nearest code vector.
        double total = 0.0;
        for (std::size_t v = 0; v < fs.size(); ++v) {
          const double own = (fs[v] - p.code_vectors[p.region_of[v]]).squaredNorm();
          total += own;
          double best = own, second = 1e300;
          for (std::size_t j = 0; j < count; ++j) {
            const double d = (fs[v] - p.code_vectors[j]).squaredNorm();
            best = std::min(best, d);
            if (j != p.region_of[v]) second = std::min(second, d);
          }
          EXPECT_LE(own, best + 1e-12) << "vertex " << v << " is not with its nearest code vector";
          if (second - own < 0.05 * second) ++near_ties;
        }
        // Every code vector is its cluster's mean.
        std::vector<Feature> sum(count, Feature::Zero());
        std::vector<double> n(count, 0.0);
        for (std::size_t v = 0; v < fs.size(); ++v) {
          sum[p.region_of[v]] += fs[v];
          n[p.region_of[v]] += 1.0;
        }
        for (std::size_t j = 0; j < count; ++j)
          EXPECT_LE((sum[j] / n[j] - p.code_vectors[j]).cwiseAbs().maxCoeff(), 1e-12) << "code vector " << j;
        EXPECT_NEAR(p.distortion, total / static_cast<double>(fs.size()), 1e-12);
        ++runs;
      }
    }
  }
  EXPECT_EQ(runs, 24u);
  // The check bit: some vertices sat close to a cluster boundary, so "nearest" was really tested.
  EXPECT_GT(near_ties, 10u);
}

TEST(Lbg, AnyCountOneToSixtyFourOnSphere) {
  const TriMesh m = makeSphere(1.0, 2000);
  const MeshTopology topology(m.triangles, m.vertices.size());
  const PositionView view = PositionView::of(m.vertices);
  std::size_t repaired = 0;
  for (std::size_t count = 1; count <= 64; ++count) {
    SCOPED_TRACE("count " + std::to_string(count));
    const Partition p = partitionLBG(topology, view, count);
    expectValidPartition(m, p, count);
    EXPECT_EQ(p.disconnected_regions, 0u);
    const std::vector<std::size_t> pieces = test::regionPieces(m.vertices.size(), m.triangles, p.region_of, count);
    for (std::size_t r = 0; r < count; ++r) EXPECT_EQ(pieces[r], 1u) << "region " << r;
    repaired += p.islands_reassigned;
  }
  // On a smooth uniform sphere LBG's cells are connected by themselves: the repair pass must find
  // nothing to move (measured 0 for every count). Islands here would mean a broken assignment step,
  // or a repair pass that moves vertices it should not.
  EXPECT_EQ(repaired, 0u);
}

TEST(Lbg, PowerOfTwoDoublingWithoutAnyCount) {
  const TriMesh m = makeTorus(1.0, 0.3, 1500);
  PartitionSettings s;
  s.any_count = false;
  for (std::size_t count : {1u, 2u, 4u, 8u, 16u, 32u}) {
    SCOPED_TRACE("count " + std::to_string(count));
    const Partition p = run(m, count, s);
    expectValidPartition(m, p, count);
    EXPECT_EQ(p.disconnected_regions, 0u);
  }
}

// ---------------------------------------------------------------------------------------------
// Thesis §5.1.2: C(1 ± ε) cannot split a cluster whose mean is the origin.

TEST(Partition, ThesisSplitFailsOnCubeAtOriginPrincipalDoesNot) {
  const TriMesh cube = makeBox(Vec3(1.0, 1.0, 1.0), 600);
  const MeshTopology topology(cube.triangles, cube.vertices.size());
  const PositionView view = PositionView::of(cube.vertices);
  {
    // The premise: the feature mean is the origin (up to rounding).
    const std::vector<Feature> f = partitionFeatures(topology, view, PartitionSettings{});
    Feature mean = Feature::Zero();
    for (const Feature& x : f) mean += x;
    mean /= static_cast<double>(f.size());
    ASSERT_LT(mean.norm(), 1e-12);
  }

  PartitionSettings thesis;
  thesis.split = SplitRule::Thesis;
  const Partition t = partitionLBG(topology, view, 2, thesis);
  EXPECT_GE(t.failed_splits, 1u) << "the thesis rule split a cube centred at the origin";
  EXPECT_GE(t.empty_reseeded, 1u) << "the empty child should have been reseeded";
  expectValidPartition(cube, t, 2);  // reseeding still delivers the count

  const Partition p = partitionLBG(topology, view, 2);  // Principal is the default
  EXPECT_EQ(p.failed_splits, 0u);
  EXPECT_EQ(p.empty_reseeded, 0u);
  expectValidPartition(cube, p, 2);
  std::size_t first = 0;
  for (Index r : p.region_of) first += (r == 0) ? 1 : 0;
  const double share = static_cast<double>(first) / static_cast<double>(cube.vertices.size());
  EXPECT_GT(share, 0.35);
  EXPECT_LT(share, 0.65);

  // Fig. 5-3b: moved away from the origin, the thesis rule splits the same cube.
  TriMesh moved = cube;
  moved.translate(Vec3(3.0, 2.0, 1.0));
  const Partition tm = run(moved, 2, thesis);
  EXPECT_EQ(tm.failed_splits, 0u);
  EXPECT_EQ(tm.empty_reseeded, 0u);
}

// ---------------------------------------------------------------------------------------------
// Property test over a corpus of meshes.

struct NamedMesh {
  std::string name;
  TriMesh mesh;
};

std::vector<NamedMesh> corpus() {
  std::vector<NamedMesh> c;
  c.push_back({"sphere", makeSphere(1.0, 1200)});
  c.push_back({"torus", makeTorus(1.0, 0.35, 1200)});
  c.push_back({"u_shape", makeUShape(1.0, 1.5, 0.25, 1200)});
  c.push_back({"fork", makeFork(2.0, 0.12, 1200)});
  c.push_back({"patch", makePatch(2.0, 1.0, 40, 20)});
  c.push_back({"box_far", makeBox(Vec3(1.0, 0.5, 0.25), 800).translate(Vec3(10.0, 0.0, 0.0))});
  c.push_back({"jittered_sphere", jittered(makeSphere(1.0, 800), 7, 0.1)});
  const std::string off = "/usr/share/assimp/models/OFF/Wuson.off";
  if (std::ifstream(off).good()) {
    const test::OffMesh w = test::readOff(off);
    TriMesh m;
    m.vertices = w.vertices;
    m.triangles = w.triangles;
    c.push_back({"Wuson.off", std::move(m)});
  }
  return c;
}

TEST(Partition, CorpusRegionsConnectedAndCountsExact) {
  const std::vector<NamedMesh> meshes = corpus();
  EXPECT_EQ(meshes.size(), 8u) << "assimp-testmodels' Wuson.off is missing: the real mesh is not tested";
  std::size_t islands = 0;
  for (const NamedMesh& nm : meshes) {
    const TriMesh& m = nm.mesh;
    const MeshTopology topology(m.triangles, m.vertices.size());
    const std::size_t components = test::triangleComponents(m.vertices.size(), m.triangles);
    for (std::size_t count : {1u, 2u, 3u, 6u, 11u, 24u, 40u}) {
      SCOPED_TRACE(nm.name + " count " + std::to_string(count));
      const Partition p = partitionLBG(topology, PositionView::of(m.vertices), count);
      expectValidPartition(m, p, count);
      const std::vector<std::size_t> pieces = test::regionPieces(m.vertices.size(), m.triangles, p.region_of, count);
      std::size_t disconnected = 0;
      for (std::size_t r = 0; r < count; ++r) disconnected += pieces[r] > 1 ? 1 : 0;
      EXPECT_EQ(disconnected, p.disconnected_regions);
      if (count >= components) {
        for (std::size_t r = 0; r < count; ++r) EXPECT_EQ(pieces[r], 1u) << "region " << r;
      }
      islands += p.islands_reassigned;
    }
  }
  // The repair had work to do somewhere in the corpus (the fork's prongs, thesis Fig. 3-7).
  EXPECT_GT(islands, 0u);
}

// A body of two pieces where LBG alone hands the small piece to a region of the big one.
TEST(Partition, TwoPieceBodyGetsOneRegionPerPiece) {
  TriMesh big = makeSphere(1.0, 1500);
  TriMesh small = makeSphere(0.08, 60);
  small.translate(Vec3(1.3, 0.0, 0.0));
  const TriMesh m = merged(big, small);
  const std::size_t big_count = big.vertices.size();
  ASSERT_EQ(test::triangleComponents(m.vertices.size(), m.triangles), 2u);

  PartitionSettings raw;
  raw.connect_regions = false;
  std::size_t orphaned = 0;
  for (std::size_t count : {2u, 3u, 5u, 9u}) {
    SCOPED_TRACE("count " + std::to_string(count));
    const Partition lbg = run(m, count, raw);
    {
      std::vector<int> side(count, -1);
      std::set<Index> spanning;
      for (std::size_t v = 0; v < m.vertices.size(); ++v) {
        const int s = v < big_count ? 0 : 1;
        int& r = side[lbg.region_of[v]];
        if (r == -1) r = s;
        if (r != s) spanning.insert(lbg.region_of[v]);
      }
      orphaned += spanning.size();
    }
    const Partition p = run(m, count);
    expectValidPartition(m, p, count);
    EXPECT_EQ(p.disconnected_regions, 0u);
    const std::vector<std::size_t> pieces = test::regionPieces(m.vertices.size(), m.triangles, p.region_of, count);
    for (std::size_t r = 0; r < count; ++r) EXPECT_EQ(pieces[r], 1u) << "region " << r;
    // No region spans both pieces.
    std::vector<int> side(count, -1);
    for (std::size_t v = 0; v < m.vertices.size(); ++v) {
      const int s = v < big_count ? 0 : 1;
      if (side[p.region_of[v]] == -1) side[p.region_of[v]] = s;
      EXPECT_EQ(side[p.region_of[v]], s) << "region " << p.region_of[v] << " spans both pieces";
    }
  }
  EXPECT_GT(orphaned, 0u) << "LBG alone never put both pieces in one region: the piece repair was not exercised";

  // Fewer regions than pieces: accepted, each region connected inside each piece it touches.
  const Partition one = run(m, 1);
  expectValidPartition(m, one, 1);
  EXPECT_EQ(one.disconnected_regions, 1u);
}

TEST(Partition, IsolatedVerticesJoinNearestRegionButNeverSeed) {
  TriMesh m = makeSphere(1.0, 400);
  const std::size_t first_isolated = m.vertices.size();
  m.vertices.push_back(Vec3(0.0, 0.0, 1.2));
  m.vertices.push_back(Vec3(0.0, 0.0, -1.2));
  const MeshTopology topology(m.triangles, m.vertices.size());
  const PositionView view = PositionView::of(m.vertices);
  const Partition p = partitionLBG(topology, view, 6);
  expectValidPartition(m, p, 6);
  EXPECT_EQ(p.disconnected_regions, 0u);
  const std::vector<Feature> f = partitionFeatures(topology, view, PartitionSettings{});
  for (std::size_t v = first_isolated; v < m.vertices.size(); ++v) {
    std::size_t nearest = 0;
    for (std::size_t j = 1; j < 6; ++j)
      if ((f[v] - p.code_vectors[j]).squaredNorm() < (f[v] - p.code_vectors[nearest]).squaredNorm()) nearest = j;
    EXPECT_EQ(p.region_of[v], nearest);
  }
  // count is bounded by the vertices in triangles, not all vertices.
  EXPECT_THROW(partitionLBG(topology, view, first_isolated + 1), Error);
}

TEST(Partition, ScaleFreeFeaturesIgnoreSize) {
  const TriMesh m = jittered(makeTorus(1.0, 0.4, 900), 3, 0.02);
  TriMesh big = m;
  big.scale(4.0);  // a power of two: every feature is bit-identical after dividing by R
  const Partition a = run(m, 9);
  const Partition b = run(big, 9);
  EXPECT_EQ(a.region_of, b.region_of);
}

TEST(Partition, DeterministicBitForBit) {
  const TriMesh m = jittered(makeFork(2.0, 0.15, 1500), 11, 0.01);
  for (std::size_t count : {5u, 17u}) {
    const Partition a = run(m, count);
    const Partition b = run(m, count);
    EXPECT_EQ(a.region_of, b.region_of);
    EXPECT_EQ(a.seed_vertex, b.seed_vertex);
    ASSERT_EQ(a.code_vectors.size(), b.code_vectors.size());
    EXPECT_EQ(std::memcmp(a.code_vectors.data(), b.code_vectors.data(), a.code_vectors.size() * sizeof(Feature)), 0);
    EXPECT_EQ(std::memcmp(&a.distortion, &b.distortion, sizeof(double)), 0);
    EXPECT_EQ(a.lloyd_iterations, b.lloyd_iterations);
  }
}

// ---------------------------------------------------------------------------------------------
// Bad input names the setting.

void expectSettingError(const std::function<void()>& f, const std::string& name) {
  try {
    f();
    ADD_FAILURE() << "no error for " << name;
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::InvalidSettings);
    EXPECT_NE(std::string(e.what()).find(name), std::string::npos) << e.what();
  }
}

TEST(Partition, BadSettingsNameTheSetting) {
  const TriMesh m = makeSphere(1.0, 100);
  const MeshTopology topology(m.triangles, m.vertices.size());
  const PositionView view = PositionView::of(m.vertices);
  auto with = [&](auto change, std::size_t count = 4) {
    return [&, change, count] {
      PartitionSettings s;
      change(s);
      partitionLBG(topology, view, count, s);
    };
  };
  expectSettingError(with([](PartitionSettings& s) { s.epsilon = 0.0; }), "epsilon");
  expectSettingError(with([](PartitionSettings& s) { s.epsilon = 1.0; }), "epsilon");
  expectSettingError(with([](PartitionSettings& s) { s.epsilon = std::nan(""); }), "epsilon");
  expectSettingError(with([](PartitionSettings& s) { s.normal_weight = -0.1; }), "normal_weight");
  expectSettingError(with([](PartitionSettings& s) { s.normal_weight = INFINITY; }), "normal_weight");
  expectSettingError(with([](PartitionSettings& s) { s.max_lloyd_iterations = 0; }), "max_lloyd_iterations");
  expectSettingError(with([](PartitionSettings&) {}, 0), "count");
  expectSettingError(with([](PartitionSettings&) {}, m.vertices.size() + 1), "count");
  expectSettingError(with([](PartitionSettings& s) { s.any_count = false; }, 3), "any_count");
  expectSettingError(with([](PartitionSettings& s) { s.any_count = false; }, 3), "count");
  // The extremes of the range are accepted.
  EXPECT_NO_THROW(partitionLBG(topology, view, m.vertices.size()));
  PartitionSettings zero_w;
  zero_w.normal_weight = 0.0;
  EXPECT_NO_THROW(partitionLBG(topology, view, 1, zero_w));
}

TEST(Partition, RejectsBadPositions) {
  TriMesh m = makeSphere(1.0, 100);
  const MeshTopology topology(m.triangles, m.vertices.size());
  m.vertices[5].y() = std::nan("");
  EXPECT_THROW(partitionLBG(topology, PositionView::of(m.vertices), 4), Error);
  std::vector<Vec3> short_view(m.vertices.begin(), m.vertices.end() - 1);
  EXPECT_THROW(partitionLBG(topology, PositionView::of(short_view), 4), Error);
}

}  // namespace
}  // namespace psc
