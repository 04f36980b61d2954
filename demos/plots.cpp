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

constexpr Pipeline kPipelines[] = {Pipeline::Sensors, Pipeline::Bounds, Pipeline::Bullet};

const char* label(Pipeline p) {
  switch (p) {
    case Pipeline::Sensors: return "particle sensors";
    case Pipeline::Bounds: return "bounds only (sensors off)";
    default: return "Bullet VF_SS";
  }
}

/// The pipelines that ran in a series, in kPipelines order.
std::vector<Pipeline> pipelinesIn(const std::vector<RunResult>& runs, const std::string& series) {
  std::vector<Pipeline> out;
  for (Pipeline p : kPipelines)
    for (const RunResult& r : runs)
      if (r.series == series && r.pipeline == p) {
        out.push_back(p);
        break;
      }
  return out;
}

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

  // --- per scene, the "scenes" series: per pipeline p (k = 0, 1, ...) the columns 2+4k ... 5+4k
  //     are collision ms mean, step ms mean, strict recall, full recall ---
  std::vector<std::pair<std::string, std::size_t>> scenes;  // (scene, resolution) in run order
  for (const RunResult& r : runs)
    if (r.series == "scenes") {
      const auto key = std::make_pair(r.scene, r.resolution);
      if (std::find(scenes.begin(), scenes.end(), key) == scenes.end()) scenes.push_back(key);
    }
  const std::vector<Pipeline> scene_pipelines = pipelinesIn(runs, "scenes");
  if (!scenes.empty()) {
    {
      std::ofstream dat = openOut(dir + "/scenes.dat");
      dat << "# scene";
      for (Pipeline p : scene_pipelines)
        for (const char* col : {"coll_mean", "step_mean", "strict", "full"}) dat << ' ' << toString(p) << '_' << col;
      dat << '\n';
      for (const auto& [scene, res] : scenes) {
        dat << '"' << scene << '"';
        for (Pipeline p : scene_pipelines) {
          const RunResult* r = findRun(runs, "scenes", scene, res, false, p);
          dat << ' ' << valueOr(r, r ? r->collision_ms_mean : 0) << ' ' << valueOr(r, r ? r->step_ms_mean : 0) << ' '
              << valueOr(r && r->has_strict, r ? r->recall_strict : 0) << ' '
              << valueOr(r && r->has_full, r ? r->recall_full : 0);
        }
        dat << '\n';
      }
    }
    const std::string common = std::string(kTerminal) +
                               "set style data histograms\nset style histogram clustered gap 1\n"
                               "set style fill solid 0.85 border -1\nset boxwidth 0.9\nset xtics rotate by -30\n"
                               "set grid ytics\nset key top left\n";
    // One bar per pipeline from column `offset` of each pipeline's block.
    const auto bars = [&](int offset, const std::string& suffix) {
      std::string plot = "plot ";
      for (std::size_t k = 0; k < scene_pipelines.size(); ++k) {
        plot += (k ? ", ''" : "'" + dir + "/scenes.dat'") + std::string(" using ") +
                std::to_string(2 + 4 * int(k) + offset) + (k ? "" : ":xtic(1)") + " title '" +
                label(scene_pipelines[k]) + suffix + "'";
      }
      return plot;
    };
    {
      std::ofstream gp = openOut(dir + "/scenes_collision_ms.gp");
      gp << common << "set output '" << dir << "/scenes_collision_ms.png'\n"
         << "set title 'Soft-soft collision time per step (mean after warm-up), per scene'\nset ylabel 'ms per step'\n"
         << "set logscale y\n"
         << bars(0, "") << '\n';
    }
    render("scenes_collision_ms");
    {
      std::ofstream gp = openOut(dir + "/scenes_step_ms.gp");
      gp << common << "set output '" << dir << "/scenes_step_ms.png'\n"
         << "set title 'Whole simulation step (mean after warm-up), per scene'\nset ylabel 'ms per step'\nset logscale y\n"
         << bars(1, "") << '\n';
    }
    render("scenes_step_ms");
    {
      std::ofstream gp = openOut(dir + "/scenes_recall.gp");
      gp << common << "set output '" << dir << "/scenes_recall.png'\n"
         << "set title 'Contact recall against the ground truth, per scene'\nset ylabel 'recall'\n"
         << "set yrange [0:1.05]\nset key below horizontal\n"
         << bars(2, ", strict") << ", " << bars(3, ", full").substr(5) << '\n';
    }
    render("scenes_recall");
  }

  // --- sweeps: per pipeline p (k = 0, 1, ...) the columns 2+3k ... 4+3k are collision ms mean,
  //     step ms mean, and collision ns per vertex (all bodies) per step ---
  for (const char* kind : {"resolution", "bodies"}) {
    const std::string series = std::string("sweep_") + kind;
    const bool by_bodies = std::string(kind) == "bodies";
    const std::vector<Pipeline> pipelines = pipelinesIn(runs, series);
    std::map<std::string, std::set<std::size_t>> xs;
    for (const RunResult& r : runs)
      if (r.series == series) xs[r.scene].insert(by_bodies ? r.bodies : r.resolution);
    const std::string xlabel = by_bodies ? "bodies" : "vertices per body";
    for (const auto& [scene, values] : xs) {
      const std::string stem = series + "_" + scene;
      const std::string data = dir + "/" + stem + ".dat";
      {
        std::ofstream dat = openOut(data);
        dat << "# " << kind;
        for (Pipeline p : pipelines)
          for (const char* col : {"coll_mean", "step_mean", "coll_ns_per_vertex"}) dat << ' ' << toString(p) << '_' << col;
        dat << '\n';
        for (std::size_t x : values) {
          dat << x;
          for (Pipeline p : pipelines) {
            const RunResult* r = findRun(runs, series, scene, x, by_bodies, p);
            const double ns_per_vertex = r && r->vertices ? r->collision_ms_mean * 1e6 / double(r->vertices) : 0.0;
            dat << ' ' << valueOr(r, r ? r->collision_ms_mean : 0) << ' ' << valueOr(r, r ? r->step_ms_mean : 0) << ' '
                << valueOr(r && r->vertices, ns_per_vertex);
          }
          dat << '\n';
        }
      }
      const auto lines = [&](int offset, const char* what, bool dashed) {
        std::string plot;
        for (std::size_t k = 0; k < pipelines.size(); ++k)
          plot += (plot.empty() ? "" : ", ") + std::string("'") + data + "' using 1:" +
                  std::to_string(2 + 3 * int(k) + offset) + " with linespoints lw 2 lc " + std::to_string(k + 1) + " pt " + std::to_string(7 - 2 * int(k)) +
                  (dashed ? " dt 2" : "") + " title '" + label(pipelines[k]) + what + "'";
        return plot;
      };
      const std::string head = std::string(kTerminal) + "set xlabel '" + xlabel + "'\nset logscale xy\nset grid\nset key top left\n";
      // One gnuplot script and PNG per figure: `extra` goes before the plot's own settings.
      const auto figure = [&](const std::string& name, const std::string& extra, const std::string& title,
                              const std::string& ylabel, const std::string& plot) {
        std::ofstream gp = openOut(dir + "/" + name + ".gp");
        gp << head << extra << "set output '" << dir << "/" << name << ".png'\n"
           << "set title '" << title << " against " << xlabel << " (" << scene << ", means after warm-up)'\n"
           << "set ylabel '" << ylabel << "'\nplot " << plot << '\n';
        gp.close();
        render(name);
      };
      figure(stem, "", "Time per step", "ms per step",
             lines(0, ": collision", false) + ", " + lines(1, ": whole step", true));
      // Collision time alone, one line per pipeline: the midphase's scaling with mesh size.
      figure(stem + "_collision_ms", "", "Soft-soft collision time per step", "collision ms per step",
             lines(0, "", false));
      figure(stem + "_ns_per_vertex", "unset logscale y\nset yrange [0:*]\n", "Collision time per vertex per step",
             "ns per vertex per step (all bodies)", lines(2, "", false));
    }
  }
  return written;
}

}  // namespace psc::demo
