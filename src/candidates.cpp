#include "candidates.h"

#include <algorithm>
#include <cmath>
#include <iterator>
#include <limits>

namespace psc::detail {

namespace {
void appendMerged(IndexRange a, IndexRange b, std::vector<Index>& out) {
  out.clear();
  out.reserve(a.size() + b.size());
  std::merge(a.begin(), a.end(), b.begin(), b.end(), std::back_inserter(out));
}
}  // namespace

void regionVertexSet(const RegionLists& lists, Index region, bool one_ring, std::vector<Index>& out) {
  appendMerged(lists.vertices.row(region), one_ring ? lists.ring.row(region) : IndexRange{}, out);
}

void regionTriangleSet(const RegionLists& lists, Index region, bool one_ring, std::vector<Index>& out) {
  appendMerged(lists.triangles.row(region), one_ring ? lists.ring_triangles.row(region) : IndexRange{}, out);
}

void collectCandidates(const Body& vb, const std::vector<Index>& vertices, const Body& tb,
                       const std::vector<Index>& triangles, double margin_sum, double motion_factor,
                       PairGridScratch& s, std::vector<std::uint64_t>& out, CandidateCounters& counters) {
  counters.vertices += vertices.size();
  counters.triangles += triangles.size();
  if (vertices.empty() || triangles.empty()) return;
  const MeshTopology& topo = *tb.topology;
  const std::size_t nt = triangles.size();

  // Triangle boxes and the box of the whole set.
  s.tri_lo.resize(nt);
  s.tri_hi.resize(nt);
  Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity());
  Vec3 hi = -lo;
  for (std::size_t k = 0; k < nt; ++k) {
    const Triangle& tri = topo.triangle(triangles[k]);
    const Vec3 a = tb.positions[tri[0]], b = tb.positions[tri[1]], c = tb.positions[tri[2]];
    s.tri_lo[k] = a.cwiseMin(b).cwiseMin(c);
    s.tri_hi[k] = a.cwiseMax(b).cwiseMax(c);
    lo = lo.cwiseMin(s.tri_lo[k]);
    hi = hi.cwiseMax(s.tri_hi[k]);
  }

  // Keep only the vertices that can reach the set's box at all.
  s.filtered.clear();
  s.radius.clear();
  for (Index v : vertices) {
    const Vec3 x = vb.positions[v];
    const double r = margin_sum + motion_factor * vb.vertexMotion(v);
    if ((x.array() >= lo.array() - r).all() && (x.array() <= hi.array() + r).all()) {
      s.filtered.push_back(v);
      s.radius.push_back(r);
    }
  }
  if (s.filtered.empty()) return;

  // Dense grid over the triangle set's box. The cell starts at the mean edge (or the margin sum
  // when larger) and grows until the grid has at most ~2 cells per triangle, so its size stays
  // O(|T|) whatever the shape of the set.
  double h = std::max({tb.mean_edge, margin_sum, 1e-9 * (hi - lo).norm(), 1e-30});
  // Counted in double: a thin set with a tiny cell has per-axis counts whose product overflows.
  std::array<long long, 3> dim{};
  for (;;) {
    double cells = 1.0;
    for (int a = 0; a < 3; ++a) cells *= std::floor((hi[a] - lo[a]) / h) + 1.0;
    if (cells <= static_cast<double>(2 * nt + 64)) break;
    h *= 1.5;
  }
  for (int a = 0; a < 3; ++a)
    dim[static_cast<std::size_t>(a)] = static_cast<long long>(std::floor((hi[a] - lo[a]) / h)) + 1;
  // Clamped before the conversion: a query box grown by a large motion term lies far outside.
  const auto cellCoord = [&](double x, int a) {
    const double c = std::floor((x - lo[a]) / h);
    return static_cast<int>(std::clamp(c, 0.0, static_cast<double>(dim[static_cast<std::size_t>(a)] - 1)));
  };
  const auto cellIndex = [&](int x, int y, int z) {
    return static_cast<std::size_t>((static_cast<long long>(z) * dim[1] + y) * dim[0] + x);
  };
  const std::size_t ncells = static_cast<std::size_t>(dim[0] * dim[1] * dim[2]);
  s.cell_lo.resize(nt);
  s.cell_hi.resize(nt);
  s.cell_start.assign(ncells + 1, 0);
  for (std::size_t k = 0; k < nt; ++k) {
    for (int a = 0; a < 3; ++a) {
      s.cell_lo[k][static_cast<std::size_t>(a)] = cellCoord(s.tri_lo[k][a], a);
      s.cell_hi[k][static_cast<std::size_t>(a)] = cellCoord(s.tri_hi[k][a], a);
    }
    for (int z = s.cell_lo[k][2]; z <= s.cell_hi[k][2]; ++z)
      for (int y = s.cell_lo[k][1]; y <= s.cell_hi[k][1]; ++y)
        for (int x = s.cell_lo[k][0]; x <= s.cell_hi[k][0]; ++x) ++s.cell_start[cellIndex(x, y, z) + 1];
  }
  for (std::size_t c = 0; c < ncells; ++c) s.cell_start[c + 1] += s.cell_start[c];
  s.cell_items.resize(s.cell_start[ncells]);
  s.cursor.assign(s.cell_start.begin(), s.cell_start.end() - 1);
  for (std::size_t k = 0; k < nt; ++k)
    for (int z = s.cell_lo[k][2]; z <= s.cell_hi[k][2]; ++z)
      for (int y = s.cell_lo[k][1]; y <= s.cell_hi[k][1]; ++y)
        for (int x = s.cell_lo[k][0]; x <= s.cell_hi[k][0]; ++x)
          s.cell_items[s.cursor[cellIndex(x, y, z)]++] = static_cast<Index>(k);

  for (std::size_t i = 0; i < s.filtered.size(); ++i) {
    const Index v = s.filtered[i];
    const double r = s.radius[i];
    const Vec3 x = vb.positions[v];
    std::array<int, 3> qlo{}, qhi{};
    for (int a = 0; a < 3; ++a) {
      qlo[static_cast<std::size_t>(a)] = cellCoord(x[a] - r, a);
      qhi[static_cast<std::size_t>(a)] = cellCoord(x[a] + r, a);
    }
    for (int z = qlo[2]; z <= qhi[2]; ++z)
      for (int y = qlo[1]; y <= qhi[1]; ++y)
        for (int xx = qlo[0]; xx <= qhi[0]; ++xx) {
          const std::size_t c = cellIndex(xx, y, z);
          for (Index e = s.cell_start[c]; e < s.cell_start[c + 1]; ++e) {
            const Index k = s.cell_items[e];
            ++counters.probes;
            // A triangle sits in every cell its box covers: report it only from the first cell
            // shared by its box and the query box, so each pair comes out once.
            const auto& cl = s.cell_lo[k];
            if (xx != std::max(cl[0], qlo[0]) || y != std::max(cl[1], qlo[1]) || z != std::max(cl[2], qlo[2]))
              continue;
            if ((x.array() >= s.tri_lo[k].array() - r).all() && (x.array() <= s.tri_hi[k].array() + r).all())
              out.push_back((std::uint64_t{v} << 32) | triangles[k]);
          }
        }
  }
}

}  // namespace psc::detail
