#include "psc/hash_grid.h"

#include "psc/error.h"

#include <algorithm>
#include <cmath>

namespace psc {

std::array<std::int64_t, 3> PointHashGrid::cellOf(const Vec3& p) const {
  // A far point with a small cell gives a cell index beyond int64 (UB to convert), and
  // forEachCandidate adds ±1 to it. Clamping is 1-Lipschitz, so points within one cell of each
  // other stay in neighbouring cells: far points only share more cells, which costs candidates.
  // A NaN query lands in cell 0; its distance tests then fail, so it finds nothing.
  constexpr double kLimit = 4.0e18;
  const auto cell = [&](double x) {
    const double c = std::floor(x / cell_);
    return static_cast<std::int64_t>(std::isnan(c) ? 0.0 : std::clamp(c, -kLimit, kLimit));
  };
  return {cell(p.x()), cell(p.y()), cell(p.z())};
}

std::uint64_t PointHashGrid::keyOf(std::int64_t x, std::int64_t y, std::int64_t z) {
  // Different cells may share a key; that only adds candidates, which callers filter by distance.
  std::uint64_t h = static_cast<std::uint64_t>(x) * 0x9E3779B97F4A7C15ull;
  h ^= static_cast<std::uint64_t>(y) * 0xC2B2AE3D27D4EB4Full + (h << 6) + (h >> 2);
  h ^= static_cast<std::uint64_t>(z) * 0x165667B19E3779F9ull + (h << 6) + (h >> 2);
  return h;
}

void PointHashGrid::build(const std::vector<Vec3>& points, double cell_size) {
  if (!(cell_size > 0.0) || !std::isfinite(cell_size))
    throw Error(ErrorCode::InvalidArgument, "hash grid cell size must be positive and finite");
  cell_ = cell_size;
  points_ = points;
  entries_.resize(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    const auto c = cellOf(points[i]);
    entries_[i] = {keyOf(c[0], c[1], c[2]), static_cast<Index>(i)};
  }
  std::sort(entries_.begin(), entries_.end(),
            [](const Entry& a, const Entry& b) { return a.key != b.key ? a.key < b.key : a.index < b.index; });
}

std::pair<std::size_t, std::size_t> PointHashGrid::cellRange(std::int64_t x, std::int64_t y, std::int64_t z) const {
  const std::uint64_t key = keyOf(x, y, z);
  const auto lo = std::lower_bound(entries_.begin(), entries_.end(), key,
                                   [](const Entry& e, std::uint64_t k) { return e.key < k; });
  auto hi = lo;
  while (hi != entries_.end() && hi->key == key) ++hi;
  return {static_cast<std::size_t>(lo - entries_.begin()), static_cast<std::size_t>(hi - entries_.begin())};
}

std::vector<std::pair<Index, Index>> PointHashGrid::pairsWithin(double radius) const {
  std::vector<std::pair<Index, Index>> out;
  const double r2 = radius * radius;
  for (std::size_t i = 0; i < points_.size(); ++i) {
    forEachCandidate(points_[i], [&](Index j) {
      if (j > i && (points_[j] - points_[i]).squaredNorm() < r2) out.emplace_back(static_cast<Index>(i), j);
    });
  }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());  // colliding keys may repeat a cell
  return out;
}

std::vector<std::pair<Index, Index>> pairsWithinBruteForce(const std::vector<Vec3>& points, double radius) {
  std::vector<std::pair<Index, Index>> out;
  const double r2 = radius * radius;
  for (std::size_t i = 0; i < points.size(); ++i)
    for (std::size_t j = i + 1; j < points.size(); ++j)
      if ((points[j] - points[i]).squaredNorm() < r2) out.emplace_back(static_cast<Index>(i), static_cast<Index>(j));
  return out;
}

}  // namespace psc
