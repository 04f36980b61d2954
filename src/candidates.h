// Private: the (vertex, triangle) candidate pairs of one flagged region pair in one direction,
// found through a small dense grid over the triangle set so the cost is about
// O(|V| + |T| + candidates), never |V|·|T| (docs/METHOD.md §6.1).
#pragma once

#include "body.h"

#include <array>
#include <cstdint>
#include <vector>

namespace psc::detail {

struct PairGridScratch {
  std::vector<Vec3> tri_lo, tri_hi;
  std::vector<std::array<int, 3>> cell_lo, cell_hi;
  std::vector<Index> cell_start, cell_items, cursor;
  std::vector<Index> filtered;
  std::vector<double> radius;
};

struct CandidateCounters {
  std::size_t vertices = 0;
  std::size_t triangles = 0;
  std::size_t probes = 0;
};

/// Appends (v << 32 | t) for every v in `vertices` of `vb` and t in `triangles` of `tb` whose
/// bounding box, grown by v's contact radius (margin_sum + motion_factor·|x_v − x_v,prev|),
/// contains x_v. Conservative: every pair closer than the radius is appended.
void collectCandidates(const Body& vb, const std::vector<Index>& vertices, const Body& tb,
                       const std::vector<Index>& triangles, double margin_sum, double motion_factor,
                       PairGridScratch& scratch, std::vector<std::uint64_t>& out, CandidateCounters& counters);

/// Vertices of region `region` (+ ring), ascending.
void regionVertexSet(const RegionLists& lists, Index region, bool one_ring, std::vector<Index>& out);
/// Triangles touching region `region` (+ ring), ascending.
void regionTriangleSet(const RegionLists& lists, Index region, bool one_ring, std::vector<Index>& out);

}  // namespace psc::detail
