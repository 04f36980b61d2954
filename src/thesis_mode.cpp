#include "thesis_mode.h"

#include <algorithm>

namespace psc::detail {

namespace {

bool candidateLess(const CandidatePair& a, const CandidatePair& b) {
  if (a.vertex_body != b.vertex_body) return a.vertex_body < b.vertex_body;
  if (a.triangle_body != b.triangle_body) return a.triangle_body < b.triangle_body;
  if (a.vertex != b.vertex) return a.vertex < b.vertex;
  return a.triangle < b.triangle;
}

}  // namespace

void flagByParticles(const Particles& ps, const SensorSettings& settings, double r_eff, PointHashGrid& grid,
                     std::vector<FlaggedPair>& flagged, StepStats& stats) {
  const std::size_t n = ps.size();
  double max_edge = 0.0, max_margin = 0.0, max_motion = 0.0;
  std::vector<double> motion(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Body& b = *ps.body[i];
    max_edge = std::max(max_edge, b.mean_edge);
    max_margin = std::max(max_margin, b.margin);
    motion[i] = b.vertexMotion(b.particle_vertex[ps.region[i]]);
    max_motion = std::max(max_motion, motion[i]);
  }
  const double max_mu = settings.mu_edge_factor * max_edge + 2.0 * max_margin + settings.motion_factor * max_motion;
  grid.build(ps.pos, std::max(r_eff, max_mu));
  const double r_eff2 = r_eff * r_eff;
  for (std::size_t i = 0; i < n; ++i) {
    const Body& bi = *ps.body[i];
    grid.forEachCandidate(ps.pos[i], [&](Index j) {
      const Body& bj = *ps.body[j];
      if (j <= i || &bj == &bi) return;
      const double d2 = (ps.pos[j] - ps.pos[i]).squaredNorm();
      if (d2 < r_eff2) ++stats.neighbor_pairs;
      const double mu = settings.mu_edge_factor * std::max(bi.mean_edge, bj.mean_edge) + bi.margin + bj.margin +
                        settings.motion_factor * std::max(motion[i], motion[j]);
      if (d2 < mu * mu) {
        FlaggedPair f;
        const bool swap = bj.id < bi.id;
        f.body_a = swap ? bj.id : bi.id;
        f.region_a = swap ? ps.region[j] : ps.region[i];
        f.body_b = swap ? bi.id : bj.id;
        f.region_b = swap ? ps.region[i] : ps.region[j];
        f.by_sensors = true;
        flagged.push_back(f);
      }
    });
  }
  std::sort(flagged.begin(), flagged.end(), flaggedLess);
  flagged.erase(std::unique(flagged.begin(), flagged.end()), flagged.end());
}

void thesisCandidates(const std::vector<FlaggedPair>& flagged, const std::function<const Body&(BodyId)>& body,
                      const SensorSettings& settings, ThesisScratch& s, std::vector<CandidatePair>& out,
                      StepStats& stats) {
  CandidateCounters counters;
  const auto direction = [&](const Body& vb, Index vregion, const Body& tb, Index tregion) {
    regionVertexSet(vb.regions, vregion, settings.one_ring, s.vset);
    regionTriangleSet(tb.regions, tregion, settings.one_ring, s.tset);
    s.keys.clear();
    collectCandidates(vb, s.vset, tb, s.tset, vb.margin + tb.margin, settings.motion_factor, s.pair, s.keys, counters);
    for (std::uint64_t k : s.keys)
      out.push_back({vb.id, static_cast<Index>(k >> 32), tb.id, static_cast<Index>(k & 0xFFFFFFFFu)});
  };
  for (const FlaggedPair& f : flagged) {
    const Body& a = body(f.body_a);
    const Body& b = body(f.body_b);
    direction(a, f.region_a, b, f.region_b);
    direction(b, f.region_b, a, f.region_a);
  }
  // Neighbouring flagged pairs share ring vertices and triangles: sort and drop repeats.
  std::sort(out.begin(), out.end(), candidateLess);
  out.erase(std::unique(out.begin(), out.end()), out.end());
  stats.candidate_vertices = counters.vertices;
  stats.candidate_triangles = counters.triangles;
  stats.candidate_probes = counters.probes;
  stats.candidate_pairs = out.size();
}

}  // namespace psc::detail
