// Private: the [beyond] bounds layer of Flagging::SensorsAndBounds. Flat boxes per body, region
// and chunk, refit from the positions every step (O(M), no tree), tested top-down only where the
// level above overlaps. Conservative: every (vertex, triangle) pair of two bodies closer than
// margin_A + margin_B + motion_factor·|x_v − x_v,prev| comes out as a candidate, exactly once.
#pragma once

#include "body.h"
#include "psc/world.h"

#include <vector>

namespace psc::detail {

/// Refits b's chunk, region and body boxes; throws psc::Error naming the first non-finite vertex.
void refitBounds(Body& b);

struct BoundsCounters {
  std::size_t chunk_pairs = 0;
  std::size_t vertices = 0;
  std::size_t triangles = 0;
  std::size_t probes = 0;
};

/// Flags the region pairs of different bodies whose grown boxes overlap and appends the candidate
/// pairs of their overlapping chunks, grouped and sorted by (vertex_body, triangle_body).
/// Region (and body) boxes are grown by `flag_pad` more on each side, so that region pairs are
/// flagged out to the collision distance μ (two pads = μ's geometric term) while chunk pairs and
/// candidates stay at the contact radius.
void collectByBounds(const std::vector<Body*>& bodies, double motion_factor, double flag_pad,
                     std::vector<FlaggedPair>& flagged, std::vector<CandidatePair>& candidates,
                     BoundsCounters& counters);

}  // namespace psc::detail
