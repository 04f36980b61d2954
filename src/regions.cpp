#include "body.h"

#include <algorithm>

namespace psc::detail {

RegionLists buildRegionLists(const MeshTopology& topology, const std::vector<Index>& region_of, std::size_t regions) {
  RegionLists out;
  std::vector<std::pair<Index, Index>> pairs;
  pairs.reserve(topology.vertexCount());
  for (Index v = 0; v < topology.vertexCount(); ++v) pairs.emplace_back(region_of[v], v);
  out.vertices = IndexRows::fromPairs(regions, pairs);

  pairs.clear();
  for (Index v = 0; v < topology.vertexCount(); ++v)
    for (Index u : topology.neighbors(v))
      if (region_of[u] != region_of[v]) pairs.emplace_back(region_of[v], u);
  out.ring = IndexRows::fromPairs(regions, pairs);

  pairs.clear();
  pairs.reserve(topology.triangleCount() * 3);
  for (Index t = 0; t < topology.triangleCount(); ++t)
    for (Index v : topology.triangle(t)) pairs.emplace_back(region_of[v], t);
  out.triangles = IndexRows::fromPairs(regions, pairs);

  pairs.clear();
  for (Index r = 0; r < regions; ++r)
    for (Index u : out.ring.row(r))
      for (Index t : topology.vertexTriangles(u)) {
        const Triangle& tri = topology.triangle(t);
        if (region_of[tri[0]] != r && region_of[tri[1]] != r && region_of[tri[2]] != r) pairs.emplace_back(r, t);
      }
  out.ring_triangles = IndexRows::fromPairs(regions, pairs);
  return out;
}

}  // namespace psc::detail

namespace psc::detail {

namespace {

// Median split along the longest axis of the box until at most `limit` vertices remain.
void splitChunks(std::vector<Index>& ids, std::size_t begin, std::size_t end, std::size_t limit,
                 const std::vector<Vec3>& positions, std::vector<std::pair<std::size_t, std::size_t>>& out) {
  if (end - begin <= limit) {
    out.emplace_back(begin, end);
    return;
  }
  Vec3 lo = positions[ids[begin]], hi = lo;
  for (std::size_t k = begin + 1; k < end; ++k) {
    const Vec3 p = positions[ids[k]];
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  Eigen::Index axis = 0;
  (hi - lo).maxCoeff(&axis);
  const std::size_t mid = begin + (end - begin) / 2;
  // A strict total order (coordinate, then index) makes the split independent of the library.
  std::nth_element(ids.begin() + static_cast<std::ptrdiff_t>(begin), ids.begin() + static_cast<std::ptrdiff_t>(mid),
                   ids.begin() + static_cast<std::ptrdiff_t>(end), [&](Index a, Index b) {
                     const double pa = positions[a][axis], pb = positions[b][axis];
                     return pa != pb ? pa < pb : a < b;
                   });
  splitChunks(ids, begin, mid, limit, positions, out);
  splitChunks(ids, mid, end, limit, positions, out);
}

}  // namespace

ForeignChunks::ForeignChunks(std::size_t vertices, Index chunks, const std::vector<std::pair<Index, Index>>& pairs)
    : slots_(2 * vertices, chunks), none_(chunks) {
  // Sorted and unique per vertex, like IndexRows::fromPairs.
  const IndexRows rows = IndexRows::fromPairs(vertices, pairs);
  for (std::size_t v = 0; v < vertices; ++v) {
    const IndexRange row = rows.row(v);
    slots_.set(2 * v, row.size() > 0 ? row[0] : chunks);
    slots_.set(2 * v + 1, row.size() > 1 ? row[1] : chunks);
    for (std::size_t k = 2; k < row.size(); ++k) extra_.emplace_back(static_cast<Index>(v), row[k]);
  }
  extra_.shrink_to_fit();
}

ChunkLists buildChunks(const MeshTopology& topology, const PositionView& positions,
                       const std::vector<Index>& region_of, std::size_t regions, std::size_t chunk_vertices) {
  ChunkLists out;
  std::vector<Index> chunk_of(topology.vertexCount(), kInvalidIndex);
  std::vector<std::pair<Index, Index>> vpairs, tpairs, bpairs;
  std::vector<Index> ids;
  std::vector<std::pair<std::size_t, std::size_t>> ranges;
  Index chunk = 0;
  out.region_begin.push_back(0);
  // One copy of the positions: the splits compare coordinates O(M log M) times, and the view may
  // point into larger records (Bullet's 256-byte nodes) of either precision.
  std::vector<Vec3> x(topology.vertexCount());
  for (Index v = 0; v < topology.vertexCount(); ++v) x[v] = positions[v];
  std::vector<std::pair<Index, Index>> members;
  members.reserve(topology.vertexCount());
  for (Index v = 0; v < topology.vertexCount(); ++v) members.emplace_back(region_of[v], v);
  const IndexRows by_region = IndexRows::fromPairs(regions, members);
  for (std::size_t r = 0; r < regions; ++r) {
    const IndexRange row = by_region.row(r);
    ids.assign(row.begin(), row.end());
    ranges.clear();
    if (!ids.empty()) splitChunks(ids, 0, ids.size(), chunk_vertices, x, ranges);
    for (const auto& range : ranges) {
      std::sort(ids.begin() + static_cast<std::ptrdiff_t>(range.first),
                ids.begin() + static_cast<std::ptrdiff_t>(range.second));
      for (std::size_t k = range.first; k < range.second; ++k) {
        chunk_of[ids[k]] = chunk;
        vpairs.emplace_back(chunk, ids[k]);
      }
      ++chunk;
    }
    out.region_begin.push_back(chunk);
    out.region_of.resize(chunk, static_cast<Index>(r));
  }
  std::vector<char> on_triangle(topology.vertexCount(), 0);
  for (Index t = 0; t < topology.triangleCount(); ++t) {
    const Triangle& tri = topology.triangle(t);
    const Index owner = chunk_of[*std::min_element(tri.begin(), tri.end())];
    tpairs.emplace_back(owner, t);
    for (Index v : tri) {
      on_triangle[v] = 1;
      if (chunk_of[v] != owner) bpairs.emplace_back(v, owner);
    }
  }
  for (Index v = 0; v < topology.vertexCount(); ++v)
    if (chunk_of[v] != kInvalidIndex && !on_triangle[v]) out.loose.push_back(v);
  out.loose.shrink_to_fit();
  out.owner = PackedIndices(topology.vertexCount(), chunk);
  for (Index v = 0; v < topology.vertexCount(); ++v) out.owner.set(v, chunk_of[v] == kInvalidIndex ? chunk : chunk_of[v]);
  out.foreign = ForeignChunks(topology.vertexCount(), chunk, bpairs);
  // Each chunk's table: its own vertices, then the foreign ones its triangles use.
  for (auto& [v, c] : bpairs) std::swap(v, c);
  const IndexRows own = IndexRows::fromPairs(chunk, vpairs);
  const IndexRows foreign = IndexRows::fromPairs(chunk, bpairs);
  const IndexRows owned = IndexRows::fromPairs(chunk, tpairs);
  out.table.reserve(own.items.size() + foreign.items.size());
  out.table_begin.reserve(chunk + 1);
  out.own_end.reserve(chunk);
  out.table_begin.push_back(0);
  for (Index c = 0; c < chunk; ++c) {
    out.table.insert(out.table.end(), own.row(c).begin(), own.row(c).end());
    out.own_end.push_back(static_cast<Index>(out.table.size()));
    out.table.insert(out.table.end(), foreign.row(c).begin(), foreign.row(c).end());
    out.table_begin.push_back(static_cast<Index>(out.table.size()));
  }
  // A chunk's base is the index after the largest gap between its triangles' indices, counted
  // around (modulo the triangle count): its offsets then span the rest.
  const Index total = static_cast<Index>(topology.triangleCount());
  out.triangle_base.assign(chunk, 0);
  std::size_t longest = 0, span = 0;
  for (Index c = 0; c < chunk; ++c) {
    longest = std::max<std::size_t>(longest, out.table_begin[c + 1] - out.table_begin[c]);
    const IndexRange mine = owned.row(c);
    if (mine.empty()) continue;
    std::size_t gap = mine[0] + total - mine[mine.size() - 1], after = 0;
    for (std::size_t k = 1; k < mine.size(); ++k)
      if (mine[k] - mine[k - 1] > gap) {
        gap = mine[k] - mine[k - 1];
        after = k;
      }
    out.triangle_base[c] = mine[after];
    span = std::max<std::size_t>(span, total - gap);
  }
  out.triangle_begin = owned.offsets;
  out.triangle_offset = PackedIndices(owned.items.size(), static_cast<Index>(span));
  out.corners = PackedIndices(3 * owned.items.size(), longest == 0 ? 0 : static_cast<Index>(longest - 1));
  for (Index c = 0; c < chunk; ++c) {
    const Index* first = out.table.data() + out.table_begin[c];
    const Index* mid = out.table.data() + out.own_end[c];
    const Index* last = out.table.data() + out.table_begin[c + 1];
    for (std::size_t k = owned.offsets[c]; k < owned.offsets[c + 1]; ++k) {
      const Index base = out.triangle_base[c];
      out.triangle_offset.set(k, owned.items[k] >= base ? owned.items[k] - base : owned.items[k] + (total - base));
      // A vertex is among the chunk's own vertices or, failing that, its foreign ones.
      for (std::size_t i = 0; i < 3; ++i) {
        const Index v = topology.triangle(owned.items[k])[i];
        const Index* at = chunk_of[v] == c ? std::lower_bound(first, mid, v) : std::lower_bound(mid, last, v);
        out.corners.set(3 * k + i, static_cast<Index>(at - first));
      }
    }
  }
  out.region_begin.shrink_to_fit();
  out.region_of.shrink_to_fit();
  return out;
}

std::vector<Triangle> ChunkLists::meshTriangles() const {
  std::vector<Triangle> out(triangle_begin.back());
  for (Index c = 0; c < count(); ++c)
    for (std::size_t k = triangle_begin[c]; k < triangle_begin[c + 1]; ++k) out[triangleId(c, k)] = triangle(c, k);
  return out;
}

std::vector<Index> ChunkLists::regionOfVertices() const {
  std::vector<Index> out(vertexCount(), kInvalidIndex);
  for (std::size_t v = 0; v < out.size(); ++v)
    if (const Index c = chunkOf(v); c != kInvalidIndex) out[v] = region_of[c];
  return out;
}

}  // namespace psc::detail
