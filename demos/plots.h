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
///   sweep_resolution_<scene>.png, sweep_bodies_<scene>.png          (the sweeps)
/// Returns the PNG paths written. Without gnuplot writes data and scripts only and returns none.
std::vector<std::string> writePlots(const std::vector<RunResult>& runs, const std::string& dir);

}  // namespace psc::demo
