// How many sensor particles each body gets (ALGORITHM.md §2, thesis §3.1): convex parts from a
// convex decomposition (HACD), the shadow-cap estimate per part, capped by the number of other
// parts in the scene that could touch it, at least 1, and a per-body override.
#pragma once

#include "psc/mesh.h"
#include "psc/types.h"

#include <vector>

namespace psc {

struct DecompositionSettings {
  double concavity = 0.05;         ///< HACD's maximum concavity, as a fraction of the body's bounding diameter. > 0
  std::size_t min_parts = 1;       ///< HACD's minimum cluster count. ≥ 1
  std::size_t max_hull_vertices = 64;  ///< HACD's vertices per convex hull. ≥ 4
  std::size_t max_input_triangles = 4000;  ///< larger meshes are clustered on a decimated copy (vertex-clustering grid); ≥ 8
};

/// One approximately convex part of a body.
struct ConvexPart {
  Vec3 center = Vec3::Zero();   ///< centre of the part's bounding sphere
  double radius = 0.0;          ///< bounding radius (units of the positions)
  std::size_t vertex_count = 0;
};

struct ConvexParts {
  std::vector<Index> part_of;   ///< part label of each vertex (size M)
  std::vector<ConvexPart> parts;
};

/// Splits a body into approximately convex parts with HACD and labels every vertex.
/// Deterministic. A convex body gives one part.
ConvexParts decomposeConvex(const MeshTopology& topology, const PositionView& positions,
                            const DecompositionSettings& settings = {});

/// The shadow-cap bound of thesis §3.1 for a part of radius R beside the scene's smallest part of
/// radius r: sin θ = r/(R + r), A/B = 2/(1 − cos θ), scaled by the packing efficiency of the
/// known optimum at equal sizes (12 caps of θ = 30° cover 12·(1 − cos 30°)/2 ≈ 0.804 of the
/// sphere) and rounded down, so equal sizes give the kissing number 12. Never below 1.
std::size_t shadowCapBound(double part_radius, double smallest_radius);

struct BudgetBody {
  ConvexParts parts;
  std::size_t override_count = 0;  ///< > 0: use exactly this many particles
};

/// Particle count per body: Σ over its parts of min(shadowCapBound(part, smallest part in the
/// scene), other parts in the scene), at least 1, at most the body's vertex count; overrides win.
std::vector<std::size_t> particleBudget(const std::vector<BudgetBody>& bodies);

}  // namespace psc
