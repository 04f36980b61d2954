// How many sensor particles each body gets (docs/METHOD.md §2, thesis §3.1): convex parts from a
// convex decomposition (HACD), the shadow-cap estimate per part, capped by the number of other
// parts in the scene that could touch it, at least 1, and a per-body override.
#pragma once

#include "psc/mesh.h"
#include "psc/types.h"

#include <vector>

namespace psc {

/// HACD runs on the body's triangles, or on a vertex-clustered copy of at most max_input_triangles
/// when the body is larger (HACD's cost grows much faster than linearly: about 0.1–0.3 s of CPU at
/// 256 triangles, seconds at 1000). Its clusters are then merged while the union of two adjacent
/// clusters stays within the concavity tolerance (HACD alone leaves closed convex bodies in
/// several clusters), and clusters of fewer than 4 vertices join a neighbour. A body whose whole
/// surface is within the tolerance is one part without running HACD.
struct DecompositionSettings {
  double concavity = 0.05;         ///< maximum concavity, as a fraction of the body's bounding-box diagonal (HACD's unit, and the merge pass's). > 0
  std::size_t min_parts = 1;       ///< minimum part count (HACD's minimum cluster count; merging stops there too). ≥ 1
  std::size_t max_hull_vertices = 64;  ///< HACD's vertices per convex hull. ≥ 4
  std::size_t max_input_triangles = 256;  ///< larger meshes are decomposed on a decimated copy (vertex-clustering grid); ≥ 8
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

/// Splits a body into approximately convex parts with HACD and labels every vertex (vertices in no
/// triangle join the part with the nearest centre). Deterministic; calls are serialised internally
/// because HACD keeps global state. A convex body gives one part. Throws psc::Error for settings
/// out of range (InvalidSettings), a view of the wrong size (InvalidArgument) or non-finite
/// positions (InvalidMesh).
ConvexParts decomposeConvex(const MeshTopology& topology, const PositionView& positions,
                            const DecompositionSettings& settings = {});

/// The shadow-cap bound of thesis §3.1 for a part of radius R beside the scene's smallest part of
/// radius r: sin θ = r/(R + r), A/B = 2/(1 − cos θ), scaled by the packing efficiency of the
/// known optimum at equal sizes (12 caps of θ = 30° cover 12·(1 − cos 30°)/2 ≈ 0.804 of the
/// sphere) and rounded down, so equal sizes give the kissing number 12: the product is raised by a
/// relative 1e-12 before rounding down, because 12 exact in real arithmetic can come out as
/// 11.999… in floating point. For R ≫ r the bound grows like η·4(R/r)² with η ≈ 0.804. Never
/// below 1. Throws psc::Error(InvalidArgument) unless both radii are positive and finite.
std::size_t shadowCapBound(double part_radius, double smallest_radius);

struct BudgetBody {
  ConvexParts parts;
  std::size_t override_count = 0;  ///< > 0: use exactly this many particles
};

/// Particle count per body: Σ over its parts of min(shadowCapBound(part, smallest part in the
/// scene), other parts in the scene), at least 1, at most the body's vertex count; overrides win.
/// "Other parts" are the parts of the other bodies: a body's own parts never touch it in the
/// particle sense (same-body particles do not pull), so a lone body gets 1. Parts of radius 0
/// count as the smallest part. Throws psc::Error(InvalidArgument) for a body without parts and
/// without an override, or a negative or non-finite radius.
std::vector<std::size_t> particleBudget(const std::vector<BudgetBody>& bodies);

}  // namespace psc
