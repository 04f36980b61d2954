// A uniform grid over axis-aligned boxes, for the references that must not be quadratic (the demos'
// ground truth, penetration, crossing and tunnelling counts): which items' boxes meet a query box,
// each item reported once, without testing every item.
#pragma once

#include "psc/types.h"

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace psc::testkit {

/// A float at or below v, and one at or above it: for boxes kept in float that must hold the
/// double ones. Beyond the float range: the largest float, or an infinity, whichever keeps v
/// inside; a NaN gives the infinity that excludes nothing.
float floatBelow(double v);
inline float floatAbove(double v) { return -floatBelow(-v); }

/// An axis-aligned box, lo ≤ hi.
struct Box {
  Vec3 lo, hi;
  bool meets(const Box& o) const { return (lo.array() <= o.hi.array()).all() && (o.lo.array() <= hi.array()).all(); }
};

/// Item i is boxes[i] of the last build. Cells are stored compressed (CSR); a query visits the
/// cells its box covers and dedups items listed in several cells by stamps. Queries are not
/// reentrant: f must not query the same grid.
class BoxGrid {
 public:
  /// Rebuilds over `boxes`. Cells start `cell` wide (at least a billionth of the boxes' extent) and
  /// grow by 1.26× until there are at most 2·boxes + 64 of them, so that scattered boxes cannot blow
  /// the grid up. A box with a NaN coordinate is in no cell.
  void build(std::vector<Box> boxes, double cell);

  /// Calls f(item) once for every item listed in a cell that [lo, hi] covers: every item whose box
  /// meets it, and maybe more. Nothing for a query with a NaN coordinate.
  template <class F>
  void forEachInCells(const Vec3& lo, const Vec3& hi, F&& f) const;

  /// Calls f(item) once for every item whose box meets [lo, hi].
  template <class F>
  void forEachInBox(const Vec3& lo, const Vec3& hi, F&& f) const {
    const Box query{lo, hi};
    forEachInCells(lo, hi, [&](Index item) {
      if (boxes_[item].meets(query)) f(item);
    });
  }

  std::size_t size() const { return boxes_.size(); }
  const Box& box(Index item) const { return boxes_[item]; }
  /// The grid spans [origin, origin + cellSize·dims) (one cell at the origin when empty).
  const Vec3& origin() const { return origin_; }
  double cellSize() const { return cell_; }
  const std::array<std::int64_t, 3>& dims() const { return dims_; }

 private:
  /// The cells [r0..r3] × [r1..r4] × [r2..r5] that [lo, hi] covers, clamped; false if none.
  bool cellRange(const Vec3& lo, const Vec3& hi, std::int64_t r[6]) const;
  std::size_t cellIndex(std::int64_t x, std::int64_t y, std::int64_t z) const {
    return static_cast<std::size_t>((z * dims_[1] + y) * dims_[0] + x);
  }
  std::uint32_t nextStamp() const;

  std::vector<Box> boxes_;
  double cell_ = 1.0;
  Vec3 origin_ = Vec3::Zero();
  std::array<std::int64_t, 3> dims_ = {1, 1, 1};
  std::vector<std::uint32_t> offsets_{0, 0};  // CSR over cells
  std::vector<Index> items_;
  mutable std::vector<std::uint32_t> stamp_;  // per item: the query that last reported it
  mutable std::uint32_t stamp_now_ = 0;
};

template <class F>
void BoxGrid::forEachInCells(const Vec3& lo, const Vec3& hi, F&& f) const {
  std::int64_t r[6];
  if (boxes_.empty() || !cellRange(lo, hi, r)) return;
  const std::uint32_t s = nextStamp();
  for (std::int64_t z = r[2]; z <= r[5]; ++z)
    for (std::int64_t y = r[1]; y <= r[4]; ++y)
      for (std::int64_t x = r[0]; x <= r[3]; ++x) {
        const std::size_t c = cellIndex(x, y, z);
        for (std::uint32_t k = offsets_[c]; k < offsets_[c + 1]; ++k) {
          const Index item = items_[k];
          if (stamp_[item] == s) continue;
          stamp_[item] = s;
          f(item);
        }
      }
}

}  // namespace psc::testkit
