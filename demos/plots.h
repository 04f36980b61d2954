// PNG plots of benchmark results through gnuplot (a subprocess; the data and the .gp script are
// left beside each PNG so a plot can be redrawn or restyled by hand).
#pragma once

#include "runner.h"

#include <string>
#include <vector>

namespace psc::demo {

/// True when `gnuplot` runs.
bool gnuplotAvailable();

/// Writes the plots that the runs support into `dir`:
///   scenes_collision_ms.png, scenes_step_ms.png, scenes_recall.png   (series "scenes")
///   sweep_<kind>_<scene>.png                 collision and whole step against the swept value
///   sweep_<kind>_<scene>_collision_ms.png    collision ms alone, one line per pipeline
///   sweep_<kind>_<scene>_ns_per_vertex.png   collision ns per vertex per step
/// (kind = resolution: x = vertices per body; kind = bodies: x = body count). Every time is the
/// mean over the timed steps; every pipeline that ran (sensors, bounds, bullet) gets its bars/line.
/// Returns the PNG paths written. Without gnuplot writes data and scripts only and returns none.
std::vector<std::string> writePlots(const std::vector<RunResult>& runs, const std::string& dir);

}  // namespace psc::demo
