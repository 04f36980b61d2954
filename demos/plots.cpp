#include "plots.h"

#include "psc/error.h"

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>

namespace psc::demo {
namespace {

std::ofstream openOut(const std::string& path) {
  std::ofstream out(path);
  if (!out) throw Error(ErrorCode::FileError, "cannot write '" + path + "'");
  return out;
}

std::string value(double v) { return std::to_string(v); }

/// "NaN" leaves a gap in gnuplot (a missing pipeline or a run without truth).
std::string valueOr(bool present, double v) { return present ? value(v) : "NaN"; }

const RunResult* findRun(const std::vector<RunResult>& runs, const std::string& series, const std::string& scene,
                         std::size_t x, bool x_is_bodies, Pipeline p) {
  for (const RunResult& r : runs)
    if (r.series == series && r.scene == scene && r.pipeline == p && (x_is_bodies ? r.bodies : r.resolution) == x)
      return &r;
  return nullptr;
}

bool runGnuplot(const std::string& script) {
  const std::string cmd = "gnuplot '" + script + "' >/dev/null 2>&1";
  return std::system(cmd.c_str()) == 0;
}

const char* kTerminal = "set terminal pngcairo noenhanced size 1100,620 font 'sans,11'\n";

}  // namespace

bool gnuplotAvailable() { return std::system("gnuplot --version >/dev/null 2>&1") == 0; }

std::vector<std::string> writePlots(const std::vector<RunResult>& runs, const std::string& dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) throw Error(ErrorCode::FileError, "cannot create plot directory '" + dir + "': " + ec.message());
  const bool gnuplot = gnuplotAvailable();
  std::vector<std::string> written;
  const auto render = [&](const std::string& stem) {
    if (gnuplot && runGnuplot(dir + "/" + stem + ".gp")) written.push_back(dir + "/" + stem + ".png");
  };

  // --- per scene, the "scenes" series ---
  std::vector<std::pair<std::string, std::size_t>> scenes;  // (scene, resolution) in run order
  for (const RunResult& r : runs)
    if (r.series == "scenes") {
      const auto key = std::make_pair(r.scene, r.resolution);
      if (std::find(scenes.begin(), scenes.end(), key) == scenes.end()) scenes.push_back(key);
    }
  if (!scenes.empty()) {
    {
      std::ofstream dat = openOut(dir + "/scenes.dat");
      dat << "# scene sensors_coll bullet_coll sensors_step bullet_step sensors_strict bullet_strict sensors_full bullet_full\n";
      for (const auto& [scene, res] : scenes) {
        const RunResult* s = findRun(runs, "scenes", scene, res, false, Pipeline::Sensors);
        const RunResult* b = findRun(runs, "scenes", scene, res, false, Pipeline::Bullet);
        dat << '"' << scene << "\" " << valueOr(s, s ? s->collision_ms_median : 0) << ' '
            << valueOr(b, b ? b->collision_ms_median : 0) << ' ' << valueOr(s, s ? s->step_ms_median : 0) << ' '
            << valueOr(b, b ? b->step_ms_median : 0) << ' ' << valueOr(s && s->has_strict, s ? s->recall_strict : 0)
            << ' ' << valueOr(b && b->has_strict, b ? b->recall_strict : 0) << ' '
            << valueOr(s && s->has_full, s ? s->recall_full : 0) << ' ' << valueOr(b && b->has_full, b ? b->recall_full : 0)
            << '\n';
      }
    }
    const std::string common = std::string(kTerminal) +
                               "set style data histograms\nset style histogram clustered gap 1\n"
                               "set style fill solid 0.85 border -1\nset boxwidth 0.9\nset xtics rotate by -30\n"
                               "set grid ytics\nset key top left\n";
    {
      std::ofstream gp = openOut(dir + "/scenes_collision_ms.gp");
      gp << common << "set output '" << dir << "/scenes_collision_ms.png'\n"
         << "set title 'Soft-soft collision time per step (median), per scene'\nset ylabel 'ms per step'\n"
         << "set logscale y\n"
         << "plot '" << dir << "/scenes.dat' using 2:xtic(1) title 'particle sensors', '' using 3 title 'Bullet VF_SS'\n";
    }
    render("scenes_collision_ms");
    {
      std::ofstream gp = openOut(dir + "/scenes_step_ms.gp");
      gp << common << "set output '" << dir << "/scenes_step_ms.png'\n"
         << "set title 'Whole simulation step (median), per scene'\nset ylabel 'ms per step'\nset logscale y\n"
         << "plot '" << dir << "/scenes.dat' using 4:xtic(1) title 'particle sensors', '' using 5 title 'Bullet VF_SS'\n";
    }
    render("scenes_step_ms");
    {
      std::ofstream gp = openOut(dir + "/scenes_recall.gp");
      gp << common << "set output '" << dir << "/scenes_recall.png'\n"
         << "set title 'Contact recall against the ground truth, per scene'\nset ylabel 'recall'\n"
         << "set yrange [0:1.1]\nset key top right horizontal\n"
         << "plot '" << dir << "/scenes.dat' using 6:xtic(1) title 'sensors, strict', '' using 7 title 'Bullet, strict', "
         << "'' using 8 title 'sensors, full', '' using 9 title 'Bullet, full'\n";
    }
    render("scenes_recall");
  }

  // --- sweeps ---
  for (const char* kind : {"resolution", "bodies"}) {
    const std::string series = std::string("sweep_") + kind;
    const bool by_bodies = std::string(kind) == "bodies";
    std::map<std::string, std::set<std::size_t>> xs;
    for (const RunResult& r : runs)
      if (r.series == series) xs[r.scene].insert(by_bodies ? r.bodies : r.resolution);
    for (const auto& [scene, values] : xs) {
      const std::string stem = series + "_" + scene;
      {
        std::ofstream dat = openOut(dir + "/" + stem + ".dat");
        dat << "# " << kind << " sensors_coll bullet_coll sensors_step bullet_step\n";
        for (std::size_t x : values) {
          const RunResult* s = findRun(runs, series, scene, x, by_bodies, Pipeline::Sensors);
          const RunResult* b = findRun(runs, series, scene, x, by_bodies, Pipeline::Bullet);
          dat << x << ' ' << valueOr(s, s ? s->collision_ms_median : 0) << ' ' << valueOr(b, b ? b->collision_ms_median : 0)
              << ' ' << valueOr(s, s ? s->step_ms_median : 0) << ' ' << valueOr(b, b ? b->step_ms_median : 0) << '\n';
        }
      }
      {
        std::ofstream gp = openOut(dir + "/" + stem + ".gp");
        gp << kTerminal << "set output '" << dir << "/" << stem << ".png'\n"
           << "set title 'Time per step against " << (by_bodies ? "body count" : "vertices per body") << " (" << scene
           << ", medians)'\n"
           << "set xlabel '" << (by_bodies ? "bodies" : "vertices per body") << "'\nset ylabel 'ms per step'\n"
           << "set logscale xy\nset grid\nset key top left\n"
           << "plot '" << dir << "/" << stem << ".dat' using 1:2 with linespoints lw 2 pt 7 title 'sensors: collision', "
           << "'' using 1:3 with linespoints lw 2 pt 5 title 'Bullet VF_SS: collision', "
           << "'' using 1:4 with linespoints dt 2 pt 6 title 'sensors: whole step', "
           << "'' using 1:5 with linespoints dt 2 pt 4 title 'Bullet VF_SS: whole step'\n";
      }
      render(stem);
    }
  }
  return written;
}

}  // namespace psc::demo
