// libFuzzer target: the demos' mesh-file loader (assimp behind psc::demo::loadMeshFile) on
// arbitrary bytes. The first byte picks the file extension, the rest is the file. A file that
// cannot be used must end in psc::Error(FileError); a mesh that loads must be one the core accepts.
#include "mesh_file.h"

#include "psc/error.h"
#include "psc/mesh.h"

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
#include <unistd.h>

namespace {

void require(bool ok, const char* what) {
  if (ok) return;
  std::fprintf(stderr, "psc fuzz: contract broken: %s\n", what);
  std::abort();
}

// The formats the demo documents first, then a few more that assimp detects by content.
constexpr const char* kExtensions[] = {"obj", "off", "ply", "stl", "dae", "3ds", "x", "bin"};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  const char* ext = kExtensions[data[0] % (sizeof kExtensions / sizeof kExtensions[0])];
  // One file per process: parallel fuzzing jobs do not share it. The pid is padded to a fixed
  // width: the loader's work on the path (and so the coverage libFuzzer steers by) must not
  // depend on the pid, or two runs with the same seed would explore different inputs.
  char pid[16];
  std::snprintf(pid, sizeof pid, "%010ld", static_cast<long>(::getpid()));
  const std::string path = std::string("/tmp/psc_fuzz_mesh_") + pid + "." + ext;
  {
    std::ofstream f(path, std::ios::binary | std::ios::trunc);
    f.write(reinterpret_cast<const char*>(data + 1), static_cast<std::streamsize>(size - 1));
  }
  try {
    psc::TriMesh mesh = psc::demo::loadMeshFile(path);
    require(!mesh.triangles.empty(), "a loaded mesh has triangles");
    for (const psc::Triangle& t : mesh.triangles)
      require(t[0] != t[1] && t[1] != t[2] && t[0] != t[2], "no repeated index after loading");
    // The loaded mesh is valid input for the core (it may still be all degenerate by area).
    const psc::MeshTopology topo(mesh.triangles, mesh.vertices.size());
    const psc::MeshReport report = psc::validate(topo, psc::PositionView::of(mesh.vertices), path);
    require(report.isolated_vertices == 0, "the loader drops vertices no triangle uses");
    psc::demo::normalizeMesh(mesh, 1.0);
    for (const psc::Vec3& p : mesh.vertices) require(p.allFinite(), "normalizing keeps coordinates finite");
    if (mesh.vertices.size() < 2000) psc::demo::subdivideToward(mesh, 2 * mesh.vertices.size());
  } catch (const psc::Error& e) {
    require(e.code() == psc::ErrorCode::FileError || e.code() == psc::ErrorCode::InvalidMesh,
            "a bad file is reported as a file or mesh error");
  }
  std::remove(path.c_str());
  return 0;
}
