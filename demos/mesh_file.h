// Triangle meshes from files (OBJ, OFF, PLY, STL and whatever else assimp reads) for scene 8.
// A file that cannot be used gives psc::Error with a message naming the file and the problem;
// it never crashes the program.
#pragma once

#include "psc/shapes.h"

#include <string>

namespace psc::demo {

struct MeshFileInfo {
  std::size_t meshes = 0;             ///< meshes in the file, merged into one body
  std::size_t vertices_in_file = 0;   ///< before welding
  std::size_t triangles_dropped = 0;  ///< degenerate (repeated index) triangles removed
  std::size_t subdivisions = 0;       ///< midpoint subdivisions applied to reach the resolution
};

/// Reads every triangle of every mesh in the file (node transforms applied), welds identical
/// vertices and drops triangles with a repeated index. Throws psc::Error(FileError) when the file
/// is missing, unreadable, holds no triangles, or has non-finite coordinates.
TriMesh loadMeshFile(const std::string& path, MeshFileInfo* info = nullptr);

/// Centres the mesh on its bounding-box centre and scales it to bounding radius `radius`.
void normalizeMesh(TriMesh& mesh, double radius);

/// Splits every triangle into four (edge midpoints shared between neighbours) while that brings
/// the vertex count closer to `target`. Returns the number of subdivisions made.
std::size_t subdivideToward(TriMesh& mesh, std::size_t target);

}  // namespace psc::demo
