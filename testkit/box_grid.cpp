#include "psc/testkit/box_grid.h"

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <limits>
#include <utility>

namespace psc::testkit {

float floatBelow(double v) {
  // Moving v by 2^-22 of itself (and 1e-30, for floats near zero) before rounding to nearest is
  // more than the rounding can take back, without a branch per coordinate.
  const double w = v - (std::abs(v) * 0x1p-22 + 1e-30);
  return w >= -static_cast<double>(FLT_MAX) ? static_cast<float>(std::min(w, static_cast<double>(FLT_MAX)))
                                            : -std::numeric_limits<float>::infinity();
}

void BoxGrid::build(std::vector<Box> boxes, double cell) {
  boxes_ = std::move(boxes);
  const std::size_t n = boxes_.size();
  stamp_.assign(n, 0u);
  stamp_now_ = 0;
  if (n == 0) {
    origin_ = Vec3::Zero();
    dims_ = {1, 1, 1};
    offsets_.assign(2, 0u);
    items_.clear();
    return;
  }
  Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (const Box& b : boxes_) {
    if (b.lo.hasNaN() || b.hi.hasNaN()) continue;  // in no cell: must not move the grid either
    lo = lo.cwiseMin(b.lo);
    hi = hi.cwiseMax(b.hi);
  }
  const Vec3 extent = (hi - lo).cwiseMax(Vec3::Constant(1e-12));
  cell_ = std::max(cell, 1e-9 * extent.maxCoeff());
  const double cap = 2.0 * static_cast<double>(n) + 64.0;
  for (;;) {
    for (int k = 0; k < 3; ++k) dims_[k] = static_cast<std::int64_t>(std::floor(extent[k] / cell_)) + 1;
    if (static_cast<double>(dims_[0]) * static_cast<double>(dims_[1]) * static_cast<double>(dims_[2]) <= cap) break;
    cell_ *= 1.26;
  }
  origin_ = lo;
  const std::size_t cells = static_cast<std::size_t>(dims_[0] * dims_[1] * dims_[2]);
  offsets_.assign(cells + 1, 0u);
  // Two passes over the items' cells: count per cell, then fill.
  std::int64_t r[6];
  for (const Box& b : boxes_) {
    if (!cellRange(b.lo, b.hi, r)) continue;
    for (std::int64_t z = r[2]; z <= r[5]; ++z)
      for (std::int64_t y = r[1]; y <= r[4]; ++y)
        for (std::int64_t x = r[0]; x <= r[3]; ++x) ++offsets_[cellIndex(x, y, z) + 1];
  }
  for (std::size_t c = 0; c < cells; ++c) offsets_[c + 1] += offsets_[c];
  items_.resize(offsets_[cells]);
  std::vector<std::uint32_t> fill(offsets_.begin(), offsets_.end() - 1);
  for (std::size_t i = 0; i < n; ++i) {
    if (!cellRange(boxes_[i].lo, boxes_[i].hi, r)) continue;
    for (std::int64_t z = r[2]; z <= r[5]; ++z)
      for (std::int64_t y = r[1]; y <= r[4]; ++y)
        for (std::int64_t x = r[0]; x <= r[3]; ++x) items_[fill[cellIndex(x, y, z)]++] = static_cast<Index>(i);
  }
}

bool BoxGrid::cellRange(const Vec3& lo, const Vec3& hi, std::int64_t r[6]) const {
  for (int k = 0; k < 3; ++k) {
    const double a = std::floor((lo[k] - origin_[k]) / cell_);
    const double b = std::floor((hi[k] - origin_[k]) / cell_);
    if (!(b >= 0.0) || !(a < static_cast<double>(dims_[k]))) return false;  // also rejects NaN
    r[k] = std::max<std::int64_t>(0, static_cast<std::int64_t>(a));
    r[k + 3] = std::min<std::int64_t>(dims_[k] - 1, static_cast<std::int64_t>(b));
  }
  return true;
}

std::uint32_t BoxGrid::nextStamp() const {
  if (++stamp_now_ == 0) {  // wrapped: forget every old stamp
    std::fill(stamp_.begin(), stamp_.end(), 0u);
    stamp_now_ = 1;
  }
  return stamp_now_;
}

}  // namespace psc::testkit
