#include "psc/settings.h"

#include "psc/error.h"

#include <cmath>
#include <sstream>

namespace psc {

namespace {
[[noreturn]] void bad(const char* name, double value, const char* rule) {
  std::ostringstream s;
  s << name << " = " << value << " is out of range: " << rule;
  throw Error(ErrorCode::InvalidSettings, s.str());
}
}  // namespace

void validate(const SensorSettings& s) {
  if (!std::isfinite(s.mu_edge_factor) || s.mu_edge_factor < 0.5)
    bad("mu_edge_factor", s.mu_edge_factor, "must be finite and at least 0.5 (thesis §5.1.4: mu >= half the mean edge)");
  if (!std::isfinite(s.r_eff) || s.r_eff < 0.0) bad("r_eff", s.r_eff, "must be 0 (auto) or a positive length");
  if (s.max_rounds < 1) bad("max_rounds", s.max_rounds, "must be at least 1");
  if (s.rounds_per_step < 0) bad("rounds_per_step", s.rounds_per_step, "must be at least 0 (0 = until stable)");
  if (!std::isfinite(s.motion_factor) || s.motion_factor < 0.0)
    bad("motion_factor", s.motion_factor, "must be finite and not negative");
  if (s.motion_bound != MotionBound::Radius && s.motion_bound != MotionBound::Swept &&
      s.motion_bound != MotionBound::Ahead)
    bad("motion_bound", static_cast<double>(s.motion_bound), "must be MotionBound::Radius, Swept or Ahead");
  if (!std::isfinite(s.ahead_steps) || s.ahead_steps <= 0.0)
    bad("ahead_steps", s.ahead_steps, "must be finite and positive");
  if (s.motion_bound == MotionBound::Swept && s.flagging == Flagging::Sensors)
    throw Error(ErrorCode::InvalidSettings,
                "motion_bound = Swept is not supported with flagging = Sensors (the thesis's flag-only mode)");
  if (!std::isfinite(s.self_radius_edges) || s.self_radius_edges < 0.0)
    bad("self_radius_edges", s.self_radius_edges, "must be finite and not negative");
  if (!std::isfinite(s.self_rest_exclusion) || s.self_rest_exclusion < 1.0)
    bad("self_rest_exclusion", s.self_rest_exclusion, "must be finite and at least 1");
  if (s.min_region_vertices < 1)
    bad("min_region_vertices", static_cast<double>(s.min_region_vertices), "must be at least 1");
  if (s.chunk_vertices != 0 && s.chunk_vertices < 4)
    bad("chunk_vertices", static_cast<double>(s.chunk_vertices), "must be 0 (by the body's size) or at least 4");
  validate(s.partition);
  const DecompositionSettings& d = s.decomposition;
  if (!std::isfinite(d.concavity) || !(d.concavity > 0.0)) bad("decomposition.concavity", d.concavity, "must be positive");
  if (d.min_parts < 1) bad("decomposition.min_parts", static_cast<double>(d.min_parts), "must be at least 1");
  if (d.max_hull_vertices < 4)
    bad("decomposition.max_hull_vertices", static_cast<double>(d.max_hull_vertices), "must be at least 4");
  if (d.max_input_triangles < 8)
    bad("decomposition.max_input_triangles", static_cast<double>(d.max_input_triangles), "must be at least 8");
  const RepartitionSettings& r = s.repartition;
  if (r.check_every < 1) bad("repartition.check_every", r.check_every, "must be at least 1");
  if (!std::isfinite(r.area_trigger) || r.area_trigger < 1.0)
    bad("repartition.area_trigger", r.area_trigger, "must be at least 1");
  if (!std::isfinite(r.edge_stretch_trigger) || (r.edge_stretch_trigger != 0.0 && r.edge_stretch_trigger < 1.0))
    bad("repartition.edge_stretch_trigger", r.edge_stretch_trigger, "must be 0 (off) or at least 1");
}

}  // namespace psc
