// Uniform hash grid over points, used to find the particles within R_eff (and within μ) of each
// other without testing all pairs (docs/METHOD.md §4 [beyond]). Deterministic: results are sorted.
#pragma once

#include "psc/types.h"

#include <utility>
#include <vector>

namespace psc {

class PointHashGrid {
 public:
  /// Bins the points into cubic cells of edge `cell_size` (> 0, finite).
  void build(const std::vector<Vec3>& points, double cell_size);

  /// Calls f(index) for every point in the 27 cells around q: a superset of the points within
  /// `cell_size` of q, in ascending index order per cell. The caller checks the distance.
  template <class F>
  void forEachCandidate(const Vec3& q, F&& f) const {
    const auto c = cellOf(q);
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) {
          const auto range = cellRange(c[0] + dx, c[1] + dy, c[2] + dz);
          for (std::size_t k = range.first; k < range.second; ++k) f(entries_[k].index);
        }
  }

  /// All pairs (i < j) with |p_i − p_j| < radius, radius ≤ cell size; sorted ascending.
  std::vector<std::pair<Index, Index>> pairsWithin(double radius) const;

  double cellSize() const { return cell_; }

 private:
  struct Entry {
    std::uint64_t key;
    Index index;
  };
  std::array<std::int64_t, 3> cellOf(const Vec3& p) const;
  static std::uint64_t keyOf(std::int64_t x, std::int64_t y, std::int64_t z);
  std::pair<std::size_t, std::size_t> cellRange(std::int64_t x, std::int64_t y, std::int64_t z) const;

  double cell_ = 1.0;
  std::vector<Vec3> points_;
  std::vector<Entry> entries_;  // sorted by (key, index)
};

/// Reference for tests: all pairs (i < j) closer than radius, by brute force.
std::vector<std::pair<Index, Index>> pairsWithinBruteForce(const std::vector<Vec3>& points, double radius);

}  // namespace psc
