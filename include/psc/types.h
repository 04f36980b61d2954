// Basic types shared by every part of the core.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>  // cross(), AngleAxis

#include <array>
#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

namespace psc {

using Vec3 = Eigen::Vector3d;           ///< All core geometry is computed in double.
using Index = std::uint32_t;            ///< Vertex, triangle, region and particle indices.
using Triangle = std::array<Index, 3>;  ///< Three vertex indices, counter-clockwise seen from outside.
using BodyId = std::uint32_t;           ///< Handle of a body in a SensorWorld; never reused.

inline constexpr Index kInvalidIndex = 0xFFFFFFFFu;
inline constexpr BodyId kInvalidBody = 0xFFFFFFFFu;

/// A read-only range of indices (C++17 stand-in for std::span<const Index>).
struct IndexRange {
  const Index* first = nullptr;
  const Index* last = nullptr;
  const Index* begin() const { return first; }
  const Index* end() const { return last; }
  std::size_t size() const { return static_cast<std::size_t>(last - first); }
  bool empty() const { return first == last; }
  Index operator[](std::size_t i) const { return first[i]; }
};

/// Compressed rows of indices (CSR): row r is items[offsets[r] .. offsets[r+1]).
struct IndexRows {
  std::vector<Index> offsets{0};
  std::vector<Index> items;
  std::size_t rows() const { return offsets.size() - 1; }
  IndexRange row(std::size_t r) const { return {items.data() + offsets[r], items.data() + offsets[r + 1]}; }
  std::size_t bytes() const { return (offsets.capacity() + items.capacity()) * sizeof(Index); }
  /// Rows from (row, item) pairs; each row's items come out sorted and unique.
  static IndexRows fromPairs(std::size_t rows, const std::vector<std::pair<Index, Index>>& pairs);
};

}  // namespace psc
