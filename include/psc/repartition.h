// Region size estimators that decide when a deforming body is re-partitioned (docs/METHOD.md §7,
// thesis §3.6, §5.1.6).
#pragma once

#include "psc/mesh.h"
#include "psc/partition.h"
#include "psc/settings.h"

#include <vector>

namespace psc {

/// [beyond] True area of every region: each triangle's area split equally among its 3 vertices,
/// summed per region. O(F).
std::vector<double> regionAreasTrue(const MeshTopology& topology, const PositionView& positions,
                                    const Partition& partition);

/// Thesis §3.6 estimator for one region: from `start` (the particle's vertex) walk in the four
/// tangent directions ±X, ±Y of the vertex normal's frame, each hop to the in-region neighbour at
/// the smallest angle to the direction (only forward hops), summing edge lengths until the walk
/// would leave the region; returns (L₊ₓ + L₋ₓ)·(L₊ᵧ + L₋ᵧ).
double regionAreaWalk(const MeshTopology& topology, const PositionView& positions, const Partition& partition,
                      Index start);

/// Areas of all regions with the chosen estimator; the walk starts at `particle_vertices[r]`.
std::vector<double> regionAreas(const MeshTopology& topology, const PositionView& positions,
                                const Partition& partition, const std::vector<Index>& particle_vertices,
                                AreaEstimator estimator);

}  // namespace psc
