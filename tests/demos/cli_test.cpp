// psc_demo as a user runs it: JSON/CSV output with the agreed keys, the scene list, and clear
// errors with a non-zero exit (never a crash) for mesh files that cannot be used.
#include "report.h"
#include "sensor_pipeline.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace psc::demo {
namespace {

namespace fs = std::filesystem;

struct Outcome {
  bool exited = false;  ///< false: killed by a signal (a crash)
  int code = -1;
  std::string output;   ///< stdout and stderr
};

Outcome run(const std::string& args) {
  const std::string cmd = std::string(PSC_DEMO_EXE) + " " + args + " 2>&1";
  Outcome o;
  FILE* pipe = popen(cmd.c_str(), "r");
  if (!pipe) return o;
  char buf[4096];
  for (std::size_t n; (n = fread(buf, 1, sizeof buf, pipe)) > 0;) o.output.append(buf, n);
  const int status = pclose(pipe);
  o.exited = WIFEXITED(status);
  o.code = o.exited ? WEXITSTATUS(status) : -1;
  return o;
}

fs::path scratch(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("psc_demo_tests_" + std::to_string(getpid())) / name;
  fs::create_directories(dir);
  return dir;
}

TEST(DemoCli, JsonAndCsvHaveTheAgreedKeys) {
  const fs::path dir = scratch("json");
  const Outcome o = run("--scene head_on --resolution 60 --steps 3 --json " + (dir / "r.json").string() + " --csv " +
                        (dir / "r.csv").string());
  ASSERT_TRUE(o.exited && o.code == 0) << o.output;
  std::ifstream in(dir / "r.json");
  const nlohmann::json doc = nlohmann::json::parse(in);  // throws (and fails) on malformed JSON
  ASSERT_TRUE(doc.contains("machine"));
  for (const char* key : {"cores", "compiler", "build_type", "bullet_version", "bullet_precision"})
    EXPECT_TRUE(doc["machine"].contains(key)) << key;
  EXPECT_GT(doc["machine"]["cores"].get<int>(), 0);
  ASSERT_TRUE(doc["runs"].is_array());
  const std::size_t expected_runs = SensorPipeline::available() ? 2 : 1;
  ASSERT_EQ(doc["runs"].size(), expected_runs);
  for (const nlohmann::json& r : doc["runs"]) {
    const std::string pipeline = r.at("pipeline").get<std::string>();
    EXPECT_TRUE(pipeline == "sensors" || pipeline == "bullet") << pipeline;
    for (const std::string& key : requiredRunKeys()) {
      const bool sensor_only = key == "flagged_pairs_per_step" || key == "particles";
      if (sensor_only && pipeline == "bullet") continue;
      EXPECT_TRUE(r.contains(key)) << pipeline << " run lacks '" << key << "'";
    }
    for (const char* key : {"recall_strict", "recall_full", "recall_strict_worst_step", "pair_recall"}) {
      EXPECT_GE(r.at(key).get<double>(), 0.0) << key;
      EXPECT_LE(r.at(key).get<double>(), 1.0) << key;
    }
    EXPECT_EQ(r.at("scene").get<std::string>(), "head_on");
    EXPECT_EQ(r.at("steps").get<int>(), 3);
  }
  std::ifstream csv(dir / "r.csv");
  std::string header, line;
  std::getline(csv, header);
  for (const std::string& key : requiredRunKeys()) EXPECT_NE(header.find(key), std::string::npos) << key;
  std::size_t rows = 0;
  while (std::getline(csv, line)) rows += !line.empty();
  EXPECT_EQ(rows, expected_runs);
}

TEST(DemoCli, WithoutTruthTheRecallKeysAreLeftOut) {
  const fs::path dir = scratch("no_truth");
  const Outcome o = run("--scene 1 --resolution 60 --steps 2 --truth none --pipeline bullet --json " +
                        (dir / "r.json").string());
  ASSERT_TRUE(o.exited && o.code == 0) << o.output;
  std::ifstream in(dir / "r.json");
  const nlohmann::json doc = nlohmann::json::parse(in);
  ASSERT_EQ(doc["runs"].size(), 1u);
  EXPECT_FALSE(doc["runs"][0].contains("recall_strict"));
  EXPECT_FALSE(doc["runs"][0].contains("recall_full"));
  EXPECT_TRUE(doc["runs"][0].contains("collision_ms_median"));
}

TEST(DemoCli, ListsScenesAndRejectsUnknownOnes) {
  const Outcome list = run("--list-scenes");
  ASSERT_TRUE(list.exited && list.code == 0) << list.output;
  for (const char* name : {"head_on", "row", "row_mixed", "interlock", "tori_pile", "mixed_pile", "cloth_ball",
                           "fast_impact", "mesh"})
    EXPECT_NE(list.output.find(name), std::string::npos) << name;
  const Outcome bad = run("--scene nonsense --steps 1");
  EXPECT_TRUE(bad.exited);
  EXPECT_EQ(bad.code, 2);
  EXPECT_NE(bad.output.find("unknown scene 'nonsense'"), std::string::npos) << bad.output;
  const Outcome sweep = run("--scene head_on --sweep bodies 2,4");
  EXPECT_EQ(sweep.code, 2);
  EXPECT_NE(sweep.output.find("fixed body count"), std::string::npos) << sweep.output;
}

TEST(DemoCli, BrokenMeshFilesGiveAClearErrorAndNonZeroExit) {
  const fs::path dir = scratch("meshes");
  const std::string models = PSC_ASSIMP_MODELS;
  std::vector<std::string> files;
  // Our own broken files: garbage, truncated, absurd header counts, a missing file, a directory.
  {
    std::ofstream(dir / "garbage.obj") << "garbage \x01\x02 not a mesh\n";
    std::ofstream(dir / "truncated.off") << "OFF\n8 12 0\n-0.5 -0.5 0.5\n0.5 -0.5";
    std::ofstream(dir / "huge_count.ply") << "ply\nformat ascii 1.0\nelement vertex 99999999999\nproperty float x\n"
                                              "property float y\nproperty float z\nend_header\n0 0 0\n";
    std::ofstream(dir / "points_only.obj") << "v 0 0 0\nv 1 0 0\nv 0 1 0\np 1\np 2\n";
    std::ofstream(dir / "empty.stl");
  }
  for (const char* f : {"garbage.obj", "truncated.off", "huge_count.ply", "points_only.obj", "empty.stl"})
    files.push_back((dir / f).string());
  files.push_back((dir / "does_not_exist.obj").string());
  files.push_back(dir.string());
  // Debian's assimp-testmodels: the deliberately broken ones.
  for (const char* f : {"invalid/empty.obj", "invalid/empty.off", "invalid/empty.ply", "invalid/malformed.obj",
                        "invalid/OutOfMemory.off", "OFF/invalid.off", "OBJ/testpoints.obj", "OBJ/testline.obj"})
    if (fs::exists(models + "/" + f)) files.push_back(models + "/" + f);
  for (const std::string& f : files) {
    const Outcome o = run("--mesh '" + f + "' --steps 2 --resolution 50 --pipeline bullet");
    EXPECT_TRUE(o.exited) << f << ": killed by a signal\n" << o.output;
    EXPECT_EQ(o.code, 2) << f << "\n" << o.output;
    EXPECT_NE(o.output.find("psc_demo: error:"), std::string::npos) << f << "\n" << o.output;
    EXPECT_NE(o.output.find(f), std::string::npos) << "the message names the file: " << o.output;
  }
}

TEST(DemoCli, ValidMeshFileRunsAsScene8) {
  const std::string cube = std::string(PSC_ASSIMP_MODELS) + "/OFF/Cube.off";
  if (!fs::exists(cube)) GTEST_SKIP() << "assimp-testmodels not installed";
  const Outcome o = run("--mesh " + cube + " --steps 3 --resolution 100 --bodies 2");
  EXPECT_TRUE(o.exited && o.code == 0) << o.output;
  EXPECT_NE(o.output.find("mesh"), std::string::npos) << o.output;
}

TEST(DemoCli, FramesAndPlots) {
  const fs::path dir = scratch("frames");
  const Outcome o = run("--scene head_on --resolution 60 --steps 3 --frames " + (dir / "f").string() + " --plot " +
                        (dir / "p").string());
  ASSERT_TRUE(o.exited && o.code == 0) << o.output;
  std::size_t pvd = 0, vtp = 0;
  for (const auto& e : fs::recursive_directory_iterator(dir / "f")) {
    pvd += e.path().extension() == ".pvd";
    vtp += e.path().extension() == ".vtp";
  }
  const std::size_t pipelines = SensorPipeline::available() ? 2 : 1;
  EXPECT_EQ(pvd, 2 * pipelines);                 // surface and particles per run
  EXPECT_EQ(vtp, pipelines * (1 + 2 * 3));       // static + 3 frames × (surface, particles)
  if (std::system("gnuplot --version >/dev/null 2>&1") == 0) {
    EXPECT_TRUE(fs::exists(dir / "p" / "scenes_collision_ms.png")) << o.output;
  }
}

}  // namespace
}  // namespace psc::demo
