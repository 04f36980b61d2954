// Private: the thesis's own flag-only midphase (Flagging::Sensors, thesis §3.5), kept so it can
// be measured beside the default. Particles of different bodies closer than μ flag their two
// regions; the candidate sets are region I (+ one vertex ring) against the triangles touching
// region J (+ ring), both directions. Not complete: a contact whose regions' particles are not
// within μ is lost (measured in tests/core/world_test.cpp and docs/METHOD.md).
#pragma once

#include "body.h"
#include "candidates.h"
#include "psc/hash_grid.h"
#include "psc/settings.h"
#include "psc/world.h"

#include <functional>
#include <vector>

namespace psc::detail {

/// The particles of one step, ordered by (body id, region).
struct Particles {
  std::vector<Body*> body;
  std::vector<Index> region;
  std::vector<Vec3> pos;
  void clear() {
    body.clear();
    region.clear();
    pos.clear();
  }
  void add(Body* b, Index r, const Vec3& p) {
    if (!p.allFinite() || p.cwiseAbs().maxCoeff() > kMaxCoordinate) checkFinite(b->positions, b->label());
    body.push_back(b);
    region.push_back(r);
    pos.push_back(p);
  }
  std::size_t size() const { return pos.size(); }
};

struct ThesisScratch {
  PairGridScratch pair;
  std::vector<Index> vset, tset;
  std::vector<std::uint64_t> keys;
};

/// Flags (sorted, unique) the region pairs whose particles are closer than μ (with margins and
/// the particles' motion term); counts neighbour pairs within R_eff.
void flagByParticles(const Particles& particles, const SensorSettings& settings, double r_eff, PointHashGrid& grid,
                     std::vector<FlaggedPair>& flagged, StepStats& stats);

/// The candidate pairs of the flagged regions' sets (thesis §3.5), sorted and unique.
void thesisCandidates(const std::vector<FlaggedPair>& flagged, const std::function<const Body&(BodyId)>& body,
                      const SensorSettings& settings, ThesisScratch& scratch, std::vector<CandidatePair>& out,
                      StepStats& stats);

}  // namespace psc::detail
