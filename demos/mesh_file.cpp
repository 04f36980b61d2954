#include "mesh_file.h"

#include "psc/error.h"

#include <assimp/Importer.hpp>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <cctype>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <map>
#include <new>
#include <unordered_map>
#include <vector>

namespace psc::demo {
namespace {

/// How much of a file the header checks read.
constexpr std::size_t kHeaderBytes = 64 * 1024;

Error fileError(const std::string& path, const std::string& what) {
  return Error(ErrorCode::FileError, "mesh file '" + path + "': " + what);
}

struct PositionKey {
  float x, y, z;
  bool operator==(const PositionKey& o) const { return x == o.x && y == o.y && z == o.z; }
};
struct PositionKeyHash {
  std::size_t operator()(const PositionKey& k) const {
    std::uint32_t b[3];
    std::memcpy(b, &k, sizeof b);
    std::uint64_t h = 1469598103934665603ull;
    for (std::uint32_t v : b) h = (h ^ v) * 1099511628211ull;
    return static_cast<std::size_t>(h);
  }
};

void collect(const aiScene* scene, TriMesh& out, MeshFileInfo& info, const std::string& path) {
  // Welding by exact position, not by assimp's JoinIdenticalVertices alone: that one keeps apart
  // vertices that differ only in normal or UV (hard edges), which would cut the soft body open.
  std::unordered_map<PositionKey, Index, PositionKeyHash> index_of;
  for (unsigned m = 0; m < scene->mNumMeshes; ++m) {
    const aiMesh* mesh = scene->mMeshes[m];
    if (!mesh || !(mesh->mPrimitiveTypes & (aiPrimitiveType_TRIANGLE | aiPrimitiveType_POLYGON))) continue;
    ++info.meshes;
    info.vertices_in_file += mesh->mNumVertices;
    std::vector<Index> remap(mesh->mNumVertices);
    for (unsigned v = 0; v < mesh->mNumVertices; ++v) {
      const aiVector3D& p = mesh->mVertices[v];
      if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
        throw fileError(path, "vertex " + std::to_string(v) + " of mesh " + std::to_string(m) +
                                  " has a non-finite coordinate");
      const auto [it, inserted] = index_of.emplace(PositionKey{p.x, p.y, p.z}, static_cast<Index>(out.vertices.size()));
      if (inserted) out.vertices.emplace_back(p.x, p.y, p.z);
      remap[v] = it->second;
    }
    // Polygons are cut into a fan from their first corner (assimp's Triangulate step is not used,
    // see loadMeshFile). A fan is exact for the convex polygons of real meshes (OFF and OBJ
    // quads); a concave polygon may come out folded but still closed.
    for (unsigned f = 0; f < mesh->mNumFaces; ++f) {
      const aiFace& face = mesh->mFaces[f];
      if (face.mNumIndices < 3) continue;  // points, lines, and empty faces of broken files
      for (unsigned k = 0; k < face.mNumIndices; ++k)
        if (face.mIndices[k] >= mesh->mNumVertices)
          throw fileError(path, "face " + std::to_string(f) + " of mesh " + std::to_string(m) +
                                    " uses vertex " + std::to_string(face.mIndices[k]) + " of " +
                                    std::to_string(mesh->mNumVertices));
      for (unsigned k = 1; k + 1 < face.mNumIndices; ++k) {
        const Triangle t{remap[face.mIndices[0]], remap[face.mIndices[k]], remap[face.mIndices[k + 1]]};
        if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) {
          ++info.triangles_dropped;
          continue;
        }
        out.triangles.push_back(t);
      }
    }
  }
}

/// Throws unless `token` is a count no larger than the file: every element takes at least one
/// byte. Without this check assimp believes a header that claims 353,535,235,358 vertices
/// (assimp-testmodels' OutOfMemory.off) and spends a minute and gigabytes before giving up.
void checkCount(const std::string& path, std::uintmax_t size, const std::string& what, const std::string& token) {
  // assimp reads the digits at the start of the token and ignores what follows them ("44ply" is
  // 44; a fuzzer found an OFF face count with letters after it that made assimp ask for 64 GB).
  std::size_t digits = 0;
  while (digits < token.size() && std::isdigit(static_cast<unsigned char>(token[digits])) != 0) ++digits;
  if (digits == 0) return;
  unsigned long long n = ~0ull;  // too large for any integer type: absurd as well
  try {
    n = std::stoull(token.substr(0, digits));
  } catch (const std::exception&) {
  }
  if (n > size)
    throw fileError(path, "the header claims " + token + " " + what + " but the file has only " +
                              std::to_string(size) + " bytes");
}

/// A PLY header must end in an end_header line before assimp sees it: assimp 5.2's PLY reader
/// loops forever on a header that never ends (a fuzzer found "ply\nformat ascii 1.0\nfoo").
/// The line must be "end_header" with nothing but spaces, tabs or a carriage return around it:
/// assimp does not take "end_header" followed by another character (a vertical tab, found by the
/// fuzzer on 2026-11-26) for the header's end, and loops just the same.
/// Element counts must fit the file. Other lines are left to assimp, which tolerates
/// non-standard ones (assimp-testmodels' Wuson.ply has a comment without "comment").
void checkPlyHeader(const std::string& path, std::uintmax_t size, std::istream& text) {
  for (std::string line; std::getline(text, line);) {
    const std::size_t first = line.find_first_not_of(" \t");
    const std::size_t last = line.find_last_not_of(" \t\r");
    if (first != std::string::npos && line.compare(first, last + 1 - first, "end_header") == 0) return;
    std::istringstream words(line);
    std::string keyword, name, count;
    words >> keyword;
    if (keyword == "element" && words >> name >> count) checkCount(path, size, name + " elements", count);
  }
  throw fileError(path, "the PLY header has no end_header line within the file's first " +
                            std::to_string(kHeaderBytes) + " bytes");
}

/// Headers are checked before assimp reads the file: OFF and PLY element counts must fit the file,
/// and a PLY header must end (see checkPlyHeader).
void checkHeader(const std::string& path, std::uintmax_t size) {
  std::ifstream in(path, std::ios::binary);
  std::string head(kHeaderBytes, '\0');
  in.read(head.data(), static_cast<std::streamsize>(head.size()));
  head.resize(static_cast<std::size_t>(in.gcount()));
  std::istringstream text(head);
  std::string first;
  std::getline(text, first);
  // assimp reads a file as PLY by its extension, or by a "ply" at its start whatever follows.
  std::string ext = std::filesystem::path(path).extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (ext == ".ply" || head.compare(0, 3, "ply") == 0) return checkPlyHeader(path, size, text);
  std::istringstream words(first);
  words >> first;
  if (first.size() >= 3 && first.compare(first.size() - 3, 3, "OFF") == 0) {
    // The counts are the first words after "OFF"; comment lines ("#" to the end of a line) may come
    // between (a review's finding, stop 46: a comment hid the counts from this check, and a 28-byte
    // file made assimp take 2.7 GB).
    std::istringstream lines(head);
    std::string uncommented, line;
    while (std::getline(lines, line)) uncommented += line.substr(0, line.find('#')) + "\n";
    std::istringstream rest(uncommented);
    std::string skip, nv, nf;
    if (rest >> skip >> nv >> nf) {
      checkCount(path, size, "vertices", nv);
      checkCount(path, size, "faces", nf);
    }
  }
}

}  // namespace

TriMesh loadMeshFile(const std::string& path, MeshFileInfo* info_out) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw fileError(path, "no such file");
  if (!std::filesystem::is_regular_file(path, ec)) throw fileError(path, "not a regular file");
  const std::uintmax_t size = std::filesystem::file_size(path, ec);
  if (ec) throw fileError(path, "cannot read its size: " + ec.message());
  if (size == 0) throw fileError(path, "the file is empty");
  checkHeader(path, size);

  Assimp::Importer importer;
  // Only post-processing steps that survive malformed input: assimp 5.2's Triangulate aborts on an
  // ai_assert and SortByPType crashes on faces with no indices (both found by scripts/fuzz on PLY
  // face lists). collect() cuts polygons into triangles and skips points and lines itself.
  const unsigned flags = aiProcess_JoinIdenticalVertices | aiProcess_PreTransformVertices | aiProcess_ValidateDataStructure;
  const aiScene* scene = nullptr;
  try {
    scene = importer.ReadFile(path, flags);
  } catch (const std::bad_alloc&) {
    throw fileError(path, "the file asks for more memory than is available (corrupt counts?)");
  } catch (const std::exception& e) {
    throw fileError(path, std::string("the reader failed: ") + e.what());
  }
  if (!scene) {
    const std::string why = importer.GetErrorString();
    throw fileError(path, why.empty() ? "assimp could not read it" : "assimp could not read it: " + why);
  }
  if (scene->mFlags & AI_SCENE_FLAGS_INCOMPLETE) throw fileError(path, "the file is incomplete (no usable meshes)");

  TriMesh out;
  MeshFileInfo info;
  collect(scene, out, info, path);
  if (out.triangles.empty()) throw fileError(path, "the file holds no triangles (points or lines only, or empty)");
  // Vertices that no triangle uses would be unreachable for the sensors: drop them.
  std::vector<Index> used(out.vertices.size(), kInvalidIndex);
  TriMesh compact;
  for (Triangle& t : out.triangles)
    for (Index& v : t) {
      if (used[v] == kInvalidIndex) {
        used[v] = static_cast<Index>(compact.vertices.size());
        compact.vertices.push_back(out.vertices[v]);
      }
      v = used[v];
    }
  compact.triangles = std::move(out.triangles);
  if (info_out) *info_out = info;
  return compact;
}

void normalizeMesh(TriMesh& mesh, double radius) {
  if (mesh.vertices.empty()) return;
  Vec3 lo = mesh.vertices[0], hi = mesh.vertices[0];
  for (const Vec3& p : mesh.vertices) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  const Vec3 c = 0.5 * (lo + hi);
  double r = 0.0;
  for (const Vec3& p : mesh.vertices) r = std::max(r, (p - c).norm());
  mesh.translate(-c);
  if (r > 0.0) mesh.scale(radius / r);
}

std::size_t subdivideToward(TriMesh& mesh, std::size_t target) {
  std::size_t done = 0;
  for (;;) {
    std::map<std::pair<Index, Index>, Index> midpoint;
    for (const Triangle& t : mesh.triangles)
      for (int k = 0; k < 3; ++k) {
        Index a = t[static_cast<std::size_t>(k)], b = t[static_cast<std::size_t>((k + 1) % 3)];
        midpoint.emplace(std::minmax(a, b), kInvalidIndex);
      }
    const std::size_t before = mesh.vertices.size();
    const std::size_t after = before + midpoint.size();
    const auto gap = [&](std::size_t n) { return n > target ? n - target : target - n; };
    if (gap(after) >= gap(before)) return done;
    for (auto& [edge, index] : midpoint) {
      index = static_cast<Index>(mesh.vertices.size());
      mesh.vertices.push_back(0.5 * (mesh.vertices[edge.first] + mesh.vertices[edge.second]));
    }
    std::vector<Triangle> split;
    split.reserve(4 * mesh.triangles.size());
    for (const Triangle& t : mesh.triangles) {
      const Index ab = midpoint.at(std::minmax(t[0], t[1]));
      const Index bc = midpoint.at(std::minmax(t[1], t[2]));
      const Index ca = midpoint.at(std::minmax(t[2], t[0]));
      split.push_back({t[0], ab, ca});
      split.push_back({ab, t[1], bc});
      split.push_back({ca, bc, t[2]});
      split.push_back({ab, bc, ca});
    }
    mesh.triangles = std::move(split);
    ++done;
  }
}

}  // namespace psc::demo
