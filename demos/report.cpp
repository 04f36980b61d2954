#include "report.h"

#include "psc/bullet/memory.h"
#include "psc/error.h"

#include <LinearMath/btScalar.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <ostream>
#include <sstream>
#include <thread>

#ifndef PSC_BUILD_TYPE
#define PSC_BUILD_TYPE "unknown"
#endif

namespace psc::demo {
namespace {

std::ofstream openOut(const std::string& path) {
  const std::filesystem::path p(path);
  std::error_code ec;
  if (p.has_parent_path()) std::filesystem::create_directories(p.parent_path(), ec);
  std::ofstream out(path);
  if (!out) throw Error(ErrorCode::FileError, "cannot write '" + path + "'");
  return out;
}

std::string fixed(double v, int digits) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", digits, v);
  return buf;
}

/// A recall, or "none" where its truth was empty (`truth` 0: nothing to find).
std::string recallText(double v, std::size_t truth, int digits) { return truth == 0 ? "none" : fixed(v, digits); }

/// Keeps 3 significant digits for small times and whole numbers for large ones.
std::string ms(double v) {
  if (v >= 100) return fixed(v, 0);
  if (v >= 10) return fixed(v, 1);
  if (v >= 1) return fixed(v, 2);
  return fixed(v, 3);
}

std::string count(double v) {
  if (v >= 1e6) return fixed(v / 1e6, 2) + "M";
  if (v >= 1e4) return fixed(v / 1e3, 1) + "k";
  return fixed(v, 0);
}

}  // namespace

MachineInfo machineInfo() {
  MachineInfo m;
  m.cores = std::thread::hardware_concurrency();
  std::ifstream cpuinfo("/proc/cpuinfo");
  for (std::string line; std::getline(cpuinfo, line);)
    if (line.rfind("model name", 0) == 0) {
      const auto colon = line.find(':');
      if (colon != std::string::npos) m.cpu = line.substr(colon + 2);
      break;
    }
#if defined(__clang__)
  m.compiler = std::string("clang ") + __clang_version__;
#elif defined(__GNUC__)
  m.compiler = std::string("g++ ") + __VERSION__;
#else
  m.compiler = "unknown";
#endif
  m.build_type = PSC_BUILD_TYPE;
  const int v = btGetVersion();
  m.bullet_version = std::to_string(v / 100) + "." + (v % 100 < 10 ? "0" : "") + std::to_string(v % 100);
  m.bullet_precision = sizeof(btScalar) == sizeof(double) ? "double" : "single";
  m.bullet_blocks = psc::bullet::largeBulletBlocksAligned() ? "line-aligned" : "default";
  const std::time_t now = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&now));
  m.date = buf;
  return m;
}

std::string machineLine(const MachineInfo& m) {
  return m.date + ", " + std::to_string(m.cores) + " cores (" + (m.cpu.empty() ? "cpu unknown" : m.cpu) +
         "), pipelines single-threaded, " + m.build_type + " build, " + m.compiler + ", Bullet " + m.bullet_version + " (" +
         m.bullet_precision + " precision, " + m.bullet_blocks + " arrays)";
}

const std::vector<std::string>& requiredRunKeys() {
  static const std::vector<std::string> keys = {
      "scene", "resolution", "bodies", "steps", "pipeline", "recall_strict", "recall_full",
      "recall_strict_worst_step", "pair_recall", "contacts_outside_truth", "exact_tests_per_step",
      "flagged_pairs_per_step", "particles", "collision_ms_mean", "step_ms_mean", "collision_ms_median",
      "step_ms_median", "max_penetration",
      "penetration_steps", "peak_rss_mb"};
  return keys;
}

nlohmann::ordered_json toJson(const MachineInfo& m) {
  return {{"cores", m.cores},           {"cpu", m.cpu},
          {"compiler", m.compiler},     {"build_type", m.build_type},
          {"bullet_version", m.bullet_version}, {"bullet_precision", m.bullet_precision},
          {"bullet_blocks", m.bullet_blocks},
          {"threads", m.threads},       {"date", m.date}};
}

nlohmann::ordered_json toJson(const RunResult& r) {
  nlohmann::ordered_json j = nlohmann::ordered_json::object();
  j["scene"] = r.scene;
  j["resolution"] = r.resolution;
  j["bodies"] = r.bodies;
  j["steps"] = r.steps;
  j["pipeline"] = runName(r);
  j["exact"] = r.exact;
  if (!r.motion_bound.empty()) j["motion_bound"] = r.motion_bound;
  if (r.pipeline != Pipeline::Bullet) j["runaway_fallback"] = r.runaway_fallback;
  if (r.pipeline != Pipeline::Bullet) j["runaway_sharing"] = r.runaway_sharing;
  if (r.pipeline != Pipeline::Bullet) j["crowded_band"] = r.crowded_band;
  if (!r.contacts.empty()) j["contact_set"] = r.contacts;
  if (r.has_strict) {
    j["recall_strict"] = r.recall_strict;
    j["recall_strict_worst_step"] = r.recall_strict_worst_step;
  }
  if (r.has_full) j["recall_full"] = r.recall_full;
  if (r.has_strict || r.has_full) j["pair_recall"] = r.pair_recall;
  if (r.has_full) j["contacts_outside_truth"] = r.contacts_outside_truth;
  j["exact_tests_per_step"] = r.exact_tests_per_step;
  if (r.has_sensor_figures) {
    j["flagged_pairs_per_step"] = r.flagged_pairs_per_step;
    j["particles"] = r.particles;
  }
  j["collision_ms_mean"] = r.collision_ms_mean;
  j["step_ms_mean"] = r.step_ms_mean;
  j["collision_ms_median"] = r.collision_ms_median;
  j["step_ms_median"] = r.step_ms_median;
  j["max_penetration"] = r.max_penetration;
  j["penetration_steps"] = r.penetration_steps;
  j["peak_rss_mb"] = r.peak_rss_mb;
  j["peak_rss_mb_first_" + std::to_string(RunResult::kEarlySteps) + "_steps"] = r.peak_rss_mb_early;
  if (r.diverged_at_step >= 0) j["diverged_at_step"] = r.diverged_at_step;
  // Beyond the required keys: the rest of the figures (docs/BENCHMARK.md) and what explains them.
  j["scene_number"] = r.scene_number;
  j["series"] = r.series;
  j["vertices"] = r.vertices;
  j["scale"] = r.scale;
  j["runaway_steps"] = r.runaway_steps;
  j["runaway_warning"] = r.runaway_warning;
  j["intersections_max"] = r.intersections_max;
  j["intersections_steps"] = r.intersections_steps;
  j["tunnelled_vertices"] = {{"total", r.tunnelled_total}, {"worst_step", r.tunnelled_worst_step}};
  j["passed_vertices"] = {{"total", r.passed_total}, {"worst_step", r.passed_worst_step}};
  j["self_collision"] = r.self_collision;
  if (r.pipeline != Pipeline::Bullet && r.self_collision) j["self_rest_bound"] = r.self_rest_bound;
  j["self_intersections_max"] = r.self_intersections_max;
  j["self_intersections_steps"] = r.self_intersections_steps;
  j["self_contacts_found"] = r.self_contacts_found_total;
  if (r.bullet_clusters > 0) {
    // Bullet's cluster runs (--bullet-clusters): k, how the self-collision ran, the cluster contacts.
    j["bullet_clusters"] = r.bullet_clusters;
    j["cluster_self"] = r.cluster_self_direct ? "direct" : "flags";
    j["cluster_contacts"] = r.cluster_contacts_total;
    j["self_cluster_contacts"] = r.self_cluster_contacts_total;
    j["cluster_self_ms_mean"] = r.stage_ms_mean.cluster_self;
  }
  if (r.has_self_truth) {
    j["self_recall_strict"] = r.self_recall_strict;
    j["truth_self_strict_contacts"] = r.self_truth_strict_total;
    j["self_recall_strict_all"] = r.self_recall_strict_all;
    j["truth_self_strict_contacts_all"] = r.self_truth_strict_all_total;
    if (r.has_full) j["self_contacts_outside_truth"] = r.self_contacts_outside_truth;
  }
  if (r.has_strict) {
    j["recall_strict_bullet_testable"] = r.recall_strict_testable;
    j["truth_strict_untestable_by_bullet"] = r.truth_strict_untestable;
  }
  if (r.has_full) j["recall_full_worst_step"] = r.recall_full_worst_step;
  j["contacts_found"] = r.contacts_found_total;
  if (r.contacts == "nearest") j["reduced_contacts"] = r.reduced_contacts_total;
  if (r.has_strict) j["truth_strict_contacts"] = r.truth_strict_total;
  if (r.has_full) j["truth_full_contacts"] = r.truth_full_total;
  if (r.has_strict || r.has_full) j["truth_ambiguous_contacts"] = r.truth_ambiguous;
  if (r.has_sensor_figures) {
    j["rounds_per_step"] = r.rounds_per_step;
    j["round_cap_hits"] = r.round_cap_hits;
    j["repartitions"] = r.repartitions;
    j["fallback_pairs"] = r.fallback_pairs;
    j["sharing_steps"] = r.sharing_steps;
    j["shared_contacts"] = r.shared_contacts;
    j["crowded_contacts"] = r.crowded_contacts;
    if (!r.pipeline_error.empty()) j["pipeline_error"] = r.pipeline_error;
    nlohmann::ordered_json counts = nlohmann::ordered_json::object();
    for (std::size_t k = 0; k < coreCounters().size() && k < r.core_counts_per_step.size(); ++k)
      counts[coreCounters()[k].first] = r.core_counts_per_step[k];
    j["core_counts_per_step"] = counts;
  }
  if (!r.flagging.empty()) j["flagging"] = r.flagging;
  j["warmup_steps"] = r.warmup;
  j["timed_steps"] = r.timed_steps;
  j["contact_steps_timed"] = r.contact_steps_timed;
  if (r.contact_steps_timed) j["collision_ms_contact_median"] = r.collision_ms_contact_median;
  j["collision_ms_max"] = r.collision_ms_max;
  j["step_ms_max"] = r.step_ms_max;
  j["detect_ms_median"] = r.stage_ms_median.detect;
  const StepTimes& mean = r.stage_ms_mean;
  const StepTimes& median = r.stage_ms_median;
  j["crossings_ms_mean"] = mean.crossings;  // measurement, not the pipeline's
  j["face_refit_ms_mean"] = mean.face_refit;
  j["face_refit_ms_median"] = median.face_refit;
  // Bullet's traversal and exact tests; for ours the pairs handed back to Bullet (normally none).
  j["traversal_exact_ms_mean"] = mean.traversal_exact;
  j["traversal_exact_ms_median"] = median.traversal_exact;
  if (r.pipeline != Pipeline::Bullet) {
    j["sensor_step_ms_mean"] = mean.sensor_step;
    j["sensor_step_ms_median"] = median.sensor_step;
    j["exact_ms_mean"] = mean.exact;
    j["exact_stage_ms_median"] = median.exact;
    j["particle_ms_mean"] = mean.particle;
    j["refit_ms_mean"] = mean.refit;
    j["flagging_ms_mean"] = mean.flagging;
    j["candidates_ms_mean"] = mean.candidates;
    j["repartition_ms_mean"] = mean.repartition;
    j["core_step_ms_mean"] = mean.core_total;
  }
  if (r.ratio_bullet_over_sensors > 0) j["ratio_bullet_over_sensors"] = r.ratio_bullet_over_sensors;
  if (r.ratio_bullet_over_bounds > 0) j["ratio_bullet_over_bounds"] = r.ratio_bullet_over_bounds;
  if (r.ratio_bounds_over_sensors > 0) j["ratio_bounds_over_sensors"] = r.ratio_bounds_over_sensors;
  j["midphase_bytes_per_vertex"] = r.midphase_bytes_per_vertex;
  j["wall_seconds"] = r.wall_seconds;
  if (!r.note.empty()) j["note"] = r.note;
  return j;
}

nlohmann::ordered_json toJson(const MachineInfo& machine, const std::vector<RunResult>& runs) {
  nlohmann::ordered_json doc;
  doc["machine"] = toJson(machine);
  doc["runs"] = nlohmann::ordered_json::array();
  for (const RunResult& r : runs) doc["runs"].push_back(toJson(r));
  return doc;
}

void printTable(std::ostream& out, const std::vector<RunResult>& runs) {
  // The run column is as wide as the longest run name (Bullet's cluster runs), at least 8.
  int name_width = 8;
  for (const RunResult& r : runs) name_width = std::max(name_width, static_cast<int>(runName(r).size()));
  const char* head = "%-12s %6s %4s %5s %-*s %15s %15s %6s %7s %8s %7s %8s %8s %6s %8s %7s %6s %6s %8s %6s\n";
  char line[512];
  std::snprintf(line, sizeof line, head, "scene", "res", "bod", "steps", name_width, "pipeline", "strict all/wst",
                "full all/wst", "pairs", "outside", "exact/st", "flag/st", "coll ms", "step ms", "B/ours", "max pen",
                "pen n", "cross", "self-x", "self rec", "MB");
  out << line;
  for (const RunResult& r : runs) {
    const std::string strict = r.has_strict ? recallText(r.recall_strict, r.truth_strict_total, 4) + "/" +
                                                  recallText(r.recall_strict_worst_step, r.truth_strict_total, 3)
                                            : "-";
    const std::string full = r.has_full ? recallText(r.recall_full, r.truth_full_total, 4) + "/" +
                                              recallText(r.recall_full_worst_step, r.truth_full_total, 3)
                                        : "-";
    const std::string pairs = (r.has_strict || r.has_full) ? recallText(r.pair_recall, r.truth_pairs_total, 3) : "-";
    const std::string outside = r.has_full ? count(double(r.contacts_outside_truth)) : "-";
    const std::string flagged = r.has_sensor_figures ? count(r.flagged_pairs_per_step) : "-";
    // Bullet's collision mean over this run's, on the rows of our pipelines.
    const double b_over_ours = r.pipeline == Pipeline::Sensors  ? r.ratio_bullet_over_sensors
                               : r.pipeline == Pipeline::Bounds ? r.ratio_bullet_over_bounds
                                                                : 0.0;
    const std::string ratio = b_over_ours > 0 ? fixed(b_over_ours, 2) : "";
    const std::string self_recall =
        r.has_self_truth ? recallText(r.self_recall_strict, r.self_truth_strict_total, 4) : "-";
    std::snprintf(line, sizeof line, head, r.scene.c_str(), std::to_string(r.resolution).c_str(),
                  std::to_string(r.bodies).c_str(), std::to_string(r.steps).c_str(), name_width, runName(r).c_str(), strict.c_str(),
                  full.c_str(), pairs.c_str(), outside.c_str(), count(r.exact_tests_per_step).c_str(), flagged.c_str(),
                  ms(r.collision_ms_mean).c_str(), ms(r.step_ms_mean).c_str(), ratio.c_str(),
                  fixed(r.max_penetration, 3).c_str(),
                  (r.diverged_at_step >= 0 ? "DIV@" + std::to_string(r.diverged_at_step)
                                           : std::to_string(r.penetration_steps)).c_str(),
                  std::to_string(r.intersections_max).c_str(), std::to_string(r.self_intersections_max).c_str(),
                  self_recall.c_str(), fixed(r.peak_rss_mb, 0).c_str());
    out << line;
  }
}

void writeJson(const std::string& path, const MachineInfo& machine, const std::vector<RunResult>& runs) {
  std::ofstream out = openOut(path);
  out << toJson(machine, runs).dump(2) << '\n';
  if (!out) throw Error(ErrorCode::FileError, "writing '" + path + "' failed");
}

void writeCsv(const std::string& path, const std::vector<RunResult>& runs) {
  std::ofstream out = openOut(path);
  // Every key that any run has, required ones first; empty cells where a key does not apply. An
  // object's members become columns of their own, named key.member.
  std::vector<std::string> keys = requiredRunKeys();
  std::vector<nlohmann::ordered_json> rows;
  for (const RunResult& r : runs) {
    const nlohmann::ordered_json run = toJson(r);
    rows.emplace_back();
    for (const auto& item : run.items()) {
      if (!item.value().is_object()) {
        rows.back()[item.key()] = item.value();
        continue;
      }
      for (const auto& member : item.value().items()) rows.back()[item.key() + "." + member.key()] = member.value();
    }
    for (const auto& item : rows.back().items())
      if (std::find(keys.begin(), keys.end(), item.key()) == keys.end()) keys.push_back(item.key());
  }
  for (std::size_t k = 0; k < keys.size(); ++k) out << (k ? "," : "") << keys[k];
  out << '\n';
  for (const nlohmann::ordered_json& row : rows) {
    for (std::size_t k = 0; k < keys.size(); ++k) {
      if (k) out << ',';
      if (!row.contains(keys[k])) continue;
      const nlohmann::ordered_json& v = row[keys[k]];
      if (v.is_string()) {
        std::string s = v.get<std::string>();
        std::string quoted = "\"";
        for (char c : s) quoted += (c == '"' ? std::string("\"\"") : std::string(1, c));
        out << quoted << '"';
      } else {
        out << v.dump();
      }
    }
    out << '\n';
  }
  if (!out) throw Error(ErrorCode::FileError, "writing '" + path + "' failed");
}

}  // namespace psc::demo
