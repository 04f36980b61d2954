#include "psc/error.h"
#include "psc/hash_grid.h"

#include <gtest/gtest.h>

#include <random>

namespace psc {
namespace {

// The grid must return exactly the brute-force pairs, and the seeded sets must be such that the
// comparison means something (some pairs, not all pairs).
TEST(HashGrid, PairsEqualBruteForceOnRandomSets) {
  std::mt19937 rng(12345);
  std::size_t total_pairs = 0, total_possible = 0;
  for (int trial = 0; trial < 40; ++trial) {
    std::uniform_int_distribution<int> count(2, 400);
    std::uniform_real_distribution<double> coord(-10.0, 10.0);
    std::uniform_real_distribution<double> radius(0.1, 4.0);
    std::vector<Vec3> pts(static_cast<std::size_t>(count(rng)));
    const Vec3 offset = trial % 4 == 0 ? Vec3(1e5, -3e4, 7e3) : Vec3::Zero();  // far from the origin too
    for (Vec3& p : pts) p = Vec3(coord(rng), coord(rng), coord(rng)) + offset;
    if (trial % 5 == 0) pts.push_back(pts.front());  // coincident points
    const double r = radius(rng);
    PointHashGrid grid;
    grid.build(pts, r * (1.0 + 0.5 * (trial % 3)));  // cell ≥ radius
    const auto fast = grid.pairsWithin(r);
    const auto slow = pairsWithinBruteForce(pts, r);
    ASSERT_EQ(fast, slow) << "trial " << trial;
    total_pairs += slow.size();
    total_possible += pts.size() * (pts.size() - 1) / 2;
  }
  EXPECT_GT(total_pairs, 1000u);
  EXPECT_LT(total_pairs, total_possible / 4);
}

TEST(HashGrid, RejectsBadCellSize) {
  PointHashGrid grid;
  std::vector<Vec3> pts{Vec3::Zero()};
  EXPECT_THROW(grid.build(pts, 0.0), Error);
  EXPECT_THROW(grid.build(pts, std::numeric_limits<double>::quiet_NaN()), Error);
}

}  // namespace
}  // namespace psc
