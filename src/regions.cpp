#include "body.h"

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
