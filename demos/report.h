// What a benchmark run prints and writes: the table, the JSON document ("machine" + "runs") and
// the CSV, all from the same RunResults.
#pragma once

#include "runner.h"

#include <nlohmann/json.hpp>

#include <iosfwd>
#include <string>
#include <vector>

namespace psc::demo {

/// Where the numbers were measured.
struct MachineInfo {
  unsigned cores = 0;
  std::string cpu, compiler, build_type, bullet_version, bullet_precision, date;
  /// "line-aligned" (psc::bullet::alignLargeBulletBlocks, the demo's default) or "default"
  /// (--bullet-default-alignment): where Bullet's large arrays, the nodes among them, start.
  std::string bullet_blocks;
  int threads = 1;  ///< the pipelines run single-threaded (the measurements between steps use a second thread)
};
MachineInfo machineInfo();

/// The JSON keys every run carries where they apply (issue 4), in output order.
const std::vector<std::string>& requiredRunKeys();

nlohmann::ordered_json toJson(const MachineInfo& machine);
nlohmann::ordered_json toJson(const RunResult& run);
nlohmann::ordered_json toJson(const MachineInfo& machine, const std::vector<RunResult>& runs);

/// One header line and one line per run; recall columns show "-" without truth.
void printTable(std::ostream& out, const std::vector<RunResult>& runs);
/// Machine line printed above tables.
std::string machineLine(const MachineInfo& m);

/// Throws psc::Error(FileError) when the file cannot be written.
void writeJson(const std::string& path, const MachineInfo& machine, const std::vector<RunResult>& runs);
void writeCsv(const std::string& path, const std::vector<RunResult>& runs);

}  // namespace psc::demo
