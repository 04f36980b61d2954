// psc::testkit against closed forms and brute force: the exact point-triangle distance (known
// cases, degenerate triangles, dense sampling, the closest point on the triangle), the brute-force
// contact set, and BoxGrid against testing every box on seeded random boxes.
#include "psc/testkit/box_grid.h"
#include "psc/testkit/reference.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

namespace psc::testkit {
namespace {

Vec3 randomVec(std::mt19937_64& rng, double lo, double hi) {
  std::uniform_real_distribution<double> u(lo, hi);
  return {u(rng), u(rng), u(rng)};
}

/// Minimum distance to points sampled on the triangle: an upper bound of the exact distance that
/// approaches it as the sampling gets finer.
double sampledDistance(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c, int n) {
  double best = INFINITY;
  for (int i = 0; i <= n; ++i)
    for (int j = 0; i + j <= n; ++j) {
      const double u = double(i) / n, v = double(j) / n;
      best = std::min(best, (p - (a + u * (b - a) + v * (c - a))).norm());
    }
  return best;
}

TEST(Distance, KnownCases) {
  const Vec3 a(0, 0, 0), b(1, 0, 0), c(0, 1, 0);
  EXPECT_DOUBLE_EQ(pointTriangleDistanceSquared({0.2, 0.2, 0.5}, a, b, c), 0.25);  // above the face
  EXPECT_DOUBLE_EQ(pointTriangleDistanceSquared({0.2, 0.2, -0.5}, a, b, c), 0.25); // below it
  EXPECT_DOUBLE_EQ(pointTriangleDistanceSquared({-1, -1, 0}, a, b, c), 2.0);      // nearest a
  EXPECT_DOUBLE_EQ(pointTriangleDistanceSquared({2, -1, 0}, a, b, c), 2.0);       // nearest b
  EXPECT_DOUBLE_EQ(pointTriangleDistanceSquared({0, 3, 4}, a, b, c), 20.0);       // nearest c
  EXPECT_DOUBLE_EQ(pointTriangleDistanceSquared({0.5, -2, 0}, a, b, c), 4.0);     // nearest edge ab
  EXPECT_DOUBLE_EQ(pointTriangleDistanceSquared({-3, 0.5, 0}, a, b, c), 9.0);     // nearest edge ca
  EXPECT_DOUBLE_EQ(pointTriangleDistance({1, 1, 0}, a, b, c), std::sqrt(0.5));    // nearest edge bc
  EXPECT_EQ(pointTriangleDistance({0.25, 0.25, 0}, a, b, c), 0.0);                // on the face
  EXPECT_NEAR((closestPointOnTriangle({0.2, 0.3, 7}, a, b, c) - Vec3(0.2, 0.3, 0)).norm(), 0.0, 1e-15);
  // The distance is the square root of the squared distance, bit for bit.
  std::mt19937_64 rng(3);
  for (int i = 0; i < 100; ++i) {
    const Vec3 p = randomVec(rng, -2, 2), q = randomVec(rng, -1, 1), r = randomVec(rng, -1, 1), s = randomVec(rng, -1, 1);
    EXPECT_EQ(pointTriangleDistance(p, q, r, s), std::sqrt(pointTriangleDistanceSquared(p, q, r, s)));
  }
}

TEST(Distance, DegenerateTrianglesFallBackToTheirEdges) {
  const Vec3 a(0, 0, 0), b(1, 0, 0);
  EXPECT_DOUBLE_EQ(pointTriangleDistanceSquared({0.5, 1, 0}, a, b, Vec3(2, 0, 0)), 1.0);  // collinear
  EXPECT_DOUBLE_EQ(pointTriangleDistanceSquared({3, 0, 1}, a, b, Vec3(2, 0, 0)), 2.0);    // past its end
  EXPECT_DOUBLE_EQ(pointTriangleDistanceSquared({0.5, 1, 0}, a, b, b), 1.0);              // a repeated corner
  EXPECT_DOUBLE_EQ(pointTriangleDistanceSquared({0, 3, 4}, a, a, a), 25.0);               // a point
  // Nearly collinear (|ab × ac|² far below 1e-24·|ab|²·|ac|²): still the distance to the segment.
  EXPECT_NEAR(pointTriangleDistance({0.5, 1, 0}, a, b, Vec3(2, 1e-14, 0)), 1.0, 1e-12);
}

TEST(Distance, MatchesDenseSamplingAndLiesOnTheTriangle) {
  std::mt19937_64 rng(7);
  int inside_face = 0;
  for (int trial = 0; trial < 300; ++trial) {
    const Vec3 a = randomVec(rng, -1, 1), b = randomVec(rng, -1, 1), c = randomVec(rng, -1, 1);
    const Vec3 p = randomVec(rng, -2, 2);
    const double exact = pointTriangleDistance(p, a, b, c);
    const double sampled = sampledDistance(p, a, b, c, 200);
    const double longest = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
    EXPECT_LE(exact, sampled + 1e-12) << "trial " << trial;
    EXPECT_LE(sampled - exact, longest / 200.0 + 1e-12) << "trial " << trial;
    // The closest point has barycentric coordinates in [0, 1] summing to 1.
    const Vec3 closest = closestPointOnTriangle(p, a, b, c);
    const Vec3 n = (b - a).cross(c - a);
    const double wa = (b - closest).cross(c - closest).dot(n) / n.squaredNorm();
    const double wb = (c - closest).cross(a - closest).dot(n) / n.squaredNorm();
    const double wc = 1.0 - wa - wb;
    EXPECT_GE(std::min({wa, wb, wc}), -1e-9) << "trial " << trial;
    EXPECT_NEAR((wa * a + wb * b + wc * c - closest).norm(), 0.0, 1e-9) << "trial " << trial;
    inside_face += std::min({wa, wb, wc}) > 1e-6;
  }
  // Both the face region and the edge and vertex regions were exercised.
  EXPECT_GT(inside_face, 10);
  EXPECT_LT(inside_face, 280);
}

TEST(Contacts, BruteForceIsEveryPairCloserThanTheRadius) {
  TriMesh tm;
  tm.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {5, 0, 0}, {6, 0, 0}, {5, 1, 0}};
  tm.triangles = {{0, 1, 2}, {3, 4, 5}};
  TriMesh vm;
  vm.vertices = {{0.2, 0.2, 0.1}, {5.2, 0.2, -0.3}, {3, 0, 0}, {0.2, 0.2, 0.5}};
  const std::vector<std::pair<Index, Index>> expected{{0, 0}, {1, 1}};
  EXPECT_EQ(bruteContacts(vm, tm, 0.4), expected);
  // Per-vertex radii and skipped pairs.
  std::vector<std::pair<Index, Index>> seen;
  forEachContact(
      vm.vertices, tm.vertices, tm.triangles, [](Index v) { return v == 3 ? 0.6 : 0.4; },
      [](Index v, Index) { return v == 1; },
      [&](Index v, Index t, double d) {
        seen.emplace_back(v, t);
        EXPECT_EQ(d, pointTriangleDistance(vm.vertices[v], tm.vertices[tm.triangles[t][0]],
                                           tm.vertices[tm.triangles[t][1]], tm.vertices[tm.triangles[t][2]]));
      });
  const std::vector<std::pair<Index, Index>> expected_radii{{0, 0}, {3, 0}};
  EXPECT_EQ(seen, expected_radii);
}

/// Seeded random boxes: mostly small, some long and some flat, clustered so that cells hold many.
std::vector<Box> randomBoxes(std::uint64_t seed, std::size_t n) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<Box> out;
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3 lo = randomVec(rng, -1, 1) * (u(rng) < 0.5 ? 0.3 : 1.0);
    Vec3 size = randomVec(rng, 0, 0.1);
    if (u(rng) < 0.1) size[static_cast<int>(3 * u(rng))] = 1.5;  // long
    if (u(rng) < 0.1) size[static_cast<int>(3 * u(rng))] = 0.0;  // flat
    out.push_back({lo, lo + size});
  }
  return out;
}

TEST(SelfExclusion, IncidentOrCloseAtRestOnly) {
  // Triangle 0 in the plane z = 0; vertex 3 above it at height h in the rest shape.
  const Triangle t{0, 1, 2};
  const double radius = 0.2, exclusion = 2.0;  // excluded below 2 × 0.2 = 0.4 at rest
  const auto rest = [](double h) { return std::vector<Vec3>{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0.2, 0.2, h}}; };
  for (Index v = 0; v < 3; ++v) EXPECT_TRUE(selfPairExcluded(v, t, rest(5.0), radius, exclusion)) << "incident " << v;
  EXPECT_TRUE(selfPairExcluded(3, t, rest(0.39), radius, exclusion));
  EXPECT_FALSE(selfPairExcluded(3, t, rest(0.41), radius, exclusion));
  EXPECT_FALSE(selfPairExcluded(3, t, rest(0.4), radius, exclusion)) << "closer than: the bound itself is not";
  EXPECT_TRUE(selfPairExcluded(3, t, rest(0.41), radius, 2.1)) << "the factor scales the bound";
  // Only the rest shape counts: where the vertex is now does not enter.
  EXPECT_FALSE(selfPairExcluded(3, t, rest(-3.0), radius, exclusion));
}

TEST(Grid, EqualsTestingEveryBoxOnRandomBoxes) {
  std::size_t reported = 0;
  for (std::uint64_t seed = 1; seed <= 20; ++seed) {
    const std::vector<Box> boxes = randomBoxes(seed, 50 + 20 * seed);
    BoxGrid grid;
    // Small cells (many per box, capped), box-sized cells, and one cell for everything.
    const double cell = seed % 3 == 0 ? 1e-3 : seed % 3 == 1 ? 0.05 : 10.0;
    grid.build(boxes, cell);
    ASSERT_EQ(grid.size(), boxes.size());
    const double cells = double(grid.dims()[0]) * double(grid.dims()[1]) * double(grid.dims()[2]);
    EXPECT_LE(cells, 2.0 * double(boxes.size()) + 64.0) << "seed " << seed;
    std::mt19937_64 rng(1000 + seed);
    for (int q = 0; q < 200; ++q) {
      const Vec3 lo = randomVec(rng, -1.5, 1.5);
      const Vec3 hi = lo + randomVec(rng, 0, q % 10 == 0 ? 2.0 : 0.2);
      const std::string what = "seed " + std::to_string(seed) + " query " + std::to_string(q);
      std::vector<Index> expected, got, in_cells;
      for (std::size_t i = 0; i < boxes.size(); ++i)
        if (boxes[i].meets({lo, hi})) expected.push_back(static_cast<Index>(i));
      grid.forEachInBox(lo, hi, [&](Index i) { got.push_back(i); });
      grid.forEachInCells(lo, hi, [&](Index i) { in_cells.push_back(i); });
      std::sort(got.begin(), got.end());
      EXPECT_TRUE(std::adjacent_find(got.begin(), got.end()) == got.end()) << what << ": an item reported twice";
      EXPECT_EQ(got, expected) << what;
      std::sort(in_cells.begin(), in_cells.end());
      EXPECT_TRUE(std::includes(in_cells.begin(), in_cells.end(), expected.begin(), expected.end())) << what;
      reported += expected.size();
    }
  }
  EXPECT_GT(reported, 1000u) << "the queries must hit boxes";
}

TEST(Grid, EmptyNaNAndRebuilt) {
  BoxGrid grid;
  grid.build({}, 1.0);
  std::size_t calls = 0;
  grid.forEachInBox(Vec3::Constant(-1e9), Vec3::Constant(1e9), [&](Index) { ++calls; });
  EXPECT_EQ(calls, 0u);
  const double nan = std::nan("");
  grid.build({{Vec3::Zero(), Vec3::Ones()}, {Vec3(nan, 0, 0), Vec3::Ones()}, {Vec3::Constant(2), Vec3::Constant(3)}}, 0.5);
  std::vector<Index> got;
  grid.forEachInBox(Vec3::Constant(-10), Vec3::Constant(10), [&](Index i) { got.push_back(i); });
  std::sort(got.begin(), got.end());
  EXPECT_EQ(got, (std::vector<Index>{0, 2})) << "a box with a NaN is in no cell";
  grid.forEachInBox(Vec3(nan, 0, 0), Vec3::Constant(10), [&](Index) { ++calls; });
  EXPECT_EQ(calls, 0u) << "a query with a NaN meets nothing";
  grid.build({{Vec3::Constant(5), Vec3::Constant(6)}}, 0.5);
  got.clear();
  grid.forEachInBox(Vec3::Constant(5.5), Vec3::Constant(5.5), [&](Index i) { got.push_back(i); });
  EXPECT_EQ(got, (std::vector<Index>{0}));
}

}  // namespace
}  // namespace psc::testkit
