// The mesh-file loader's checks before assimp (demos/mesh_file.cpp), called directly so that each
// case can be matched to its message: binary and ASCII PLY list lengths bounded by what the file
// holds, OFF faces and ASCII STL facets that assimp 5.2 would only log, and the files of those
// formats that assimp reads correctly still loading.
#include "mesh_file.h"

#include "psc/error.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace psc::demo {
namespace {

namespace fs = std::filesystem;

fs::path writeFile(const std::string& name, const std::string& bytes) {
  const fs::path dir = fs::temp_directory_path() / ("psc_mesh_file_tests_" + std::to_string(getpid()));
  fs::create_directories(dir);
  const fs::path path = dir / name;
  std::ofstream(path, std::ios::binary | std::ios::trunc).write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  return path;
}

/// The message of the FileError loading `bytes` as file `name` gives ("" and a test failure when
/// it loads or fails otherwise). The message must name the file.
std::string refusal(const std::string& name, const std::string& bytes) {
  const fs::path path = writeFile(name, bytes);
  try {
    const TriMesh mesh = loadMeshFile(path.string());
    ADD_FAILURE() << name << " loaded (" << mesh.triangles.size() << " triangles)";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::FileError) << name << ": " << e.what();
    EXPECT_NE(std::string(e.what()).find(path.string()), std::string::npos) << e.what();
    return e.what();
  }
  return "";
}

std::size_t triangles(const std::string& name, const std::string& bytes) {
  const fs::path path = writeFile(name, bytes);
  try {
    return loadMeshFile(path.string()).triangles.size();
  } catch (const Error& e) {
    ADD_FAILURE() << name << ": " << e.what();
  }
  return 0;
}

#define EXPECT_REFUSED(name, bytes, part)                                                        \
  do {                                                                                           \
    const std::string message = refusal(name, bytes);                                            \
    EXPECT_NE(message.find(part), std::string::npos) << name << " should say: " << (part) << "\n" \
                                                     << "it says: " << message;                  \
  } while (false)

// Binary PLY bodies: little- or big-endian scalars, written out byte by byte.
template <class T>
std::string bin(T v, bool big_endian) {
  std::string b(sizeof v, '\0');
  std::memcpy(b.data(), &v, sizeof v);
  if (big_endian) std::reverse(b.begin(), b.end());
  return b;
}

const char* const kTetraPoints[4][3] = {{"0", "0", "0"}, {"1", "0", "0"}, {"0", "1", "0"}, {"0", "0", "1"}};
const int kTetraFaces[4][3] = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};

std::string binaryPlyHeader(bool big_endian, const std::string& list, int faces = 4) {
  return std::string("ply\nformat ") + (big_endian ? "binary_big_endian" : "binary_little_endian") +
         " 1.0\ncomment written by mesh_file_test\nelement vertex 4\nproperty float x\nproperty float y\n"
         "property float z\nelement face " + std::to_string(faces) + "\nproperty list " + list +
         " vertex_indices\nend_header\n";
}

std::string binaryTetraVertices(bool big_endian) {
  std::string out;
  for (const auto& p : kTetraPoints)
    for (const char* c : p) out += bin(std::stof(c), big_endian);
  return out;
}

TEST(MeshFile, BinaryPlyListsLongerThanTheFileAreRefusedBeforeAssimp) {
  for (const bool be : {false, true}) {
    const std::string tag = be ? "_be" : "_le";
    // The valid tetrahedron first: the scan reads what assimp reads.
    std::string body = binaryTetraVertices(be);
    for (const auto& f : kTetraFaces) {
      body += bin<std::uint8_t>(3, be);
      for (int i : f) body += bin<std::int32_t>(i, be);
    }
    EXPECT_EQ(triangles("tetra" + tag + ".ply", binaryPlyHeader(be, "uchar int") + body), 4u);

    // One face claiming 4e9 indices: assimp 5.2 resizes the list to it first (32 GB).
    const std::string one = binaryPlyHeader(be, "uint int", 1) + binaryTetraVertices(be) +
                            bin<std::uint32_t>(4000000000u, be) + bin<std::int32_t>(0, be);
    EXPECT_REFUSED("uint_length" + tag + ".ply", one,
                   "element 'face' item 0 of 1 claims 4000000000 entries in its list 'vertex_indices' "
                   "(16000000000 bytes) but only 4 bytes of the file are left");
    // A negative int length is 4294967295 for assimp.
    const std::string negative = binaryPlyHeader(be, "int int", 1) + binaryTetraVertices(be) +
                                 bin<std::int32_t>(-1, be) + bin<std::int32_t>(0, be);
    EXPECT_REFUSED("negative_length" + tag + ".ply", negative,
                   "element 'face' item 0 of 1 gives its list 'vertex_indices' the length -1");
    // A uchar length past the end: the third face of four.
    std::string short_list = binaryTetraVertices(be);
    for (int f = 0; f < 3; ++f) {
      short_list += bin<std::uint8_t>(f == 2 ? 200 : 3, be);
      for (int i : kTetraFaces[f]) short_list += bin<std::int32_t>(i, be);
    }
    EXPECT_REFUSED("short_list" + tag + ".ply", binaryPlyHeader(be, "uchar int") + short_list,
                   "element 'face' item 2 of 4 claims 200 entries");
    // Vertex data cut short: 4 vertices of 12 bytes, 40 bytes there.
    EXPECT_REFUSED("short_vertices" + tag + ".ply", binaryPlyHeader(be, "uchar int") + binaryTetraVertices(be).substr(0, 40),
                   "the binary PLY body ends inside element 'vertex' item 3 of 4");
    // The face count byte itself missing.
    EXPECT_REFUSED("no_faces" + tag + ".ply", binaryPlyHeader(be, "uchar int") + binaryTetraVertices(be),
                   "ends inside element 'face' item 0 of 4 (property 'vertex_indices' needs 1 bytes, 0 are left)");
  }
  // Elements without properties take no bytes: their counts are bounded by the file's size in all.
  std::string many = "ply\nformat binary_little_endian 1.0\n";
  for (int i = 0; i < 40; ++i) many += "element edge 200\n";
  many += "element vertex 0\nend_header\n";
  EXPECT_REFUSED("many_empty_elements.ply", many, "the PLY header's elements claim 8000 items in all");
  // Debian's assimp-testmodels: the binary cube still loads.
  const std::string cube = "/usr/share/assimp/models/PLY/cube_binary.ply";
  if (fs::exists(cube)) {
    EXPECT_EQ(loadMeshFile(cube).triangles.size(), 12u);
  }
}

std::string asciiPly(const std::string& list, const std::string& face_lines, int faces) {
  std::string out = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
                    "element face " + std::to_string(faces) + "\nproperty list " + list + " vertex_indices\nend_header\n";
  for (const auto& p : kTetraPoints) out += std::string(p[0]) + " " + p[1] + " " + p[2] + "\n";
  return out + face_lines;
}

TEST(MeshFile, AsciiPlyListLengthsAreBoundedByTheirLine) {
  EXPECT_EQ(triangles("tetra.ply", asciiPly("uchar int", "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n", 4)), 4u);
  // A quad and a triangle, CRLF lines, a trailing colour after the list and no final newline.
  EXPECT_EQ(triangles("crlf.ply", "ply\r\nformat ascii 1.0\r\nelement vertex 4\r\nproperty float x\r\n"
                                  "property float y\r\nproperty float z\r\nelement face 2\r\n"
                                  "property list uchar int vertex_indices\r\nproperty uchar red\r\nend_header\r\n"
                                  "0 0 0\r\n1 0 0\r\n1 1 0\r\n0 0 1\r\n4 0 1 2 3 255\r\n3 0 1 3 0"),
            3u);
  // An int length of -1 is 4294967295 for assimp, which resizes the list to it (32 GB).
  EXPECT_REFUSED("negative.ply", asciiPly("int int", "-1 0 1 2\n", 1),
                 "element 'face' item 0 of 1 (line 14) gives its list 'vertex_indices' the length -1");
  EXPECT_REFUSED("huge.ply", asciiPly("uint int", "4000000000 0 1 2\n", 1),
                 "element 'face' item 0 of 1 (line 14) claims 4000000000 entries in its list 'vertex_indices' "
                 "but its line holds only 3");
  // One index short: assimp fills the list with whatever its line buffer held before.
  EXPECT_REFUSED("short.ply", asciiPly("uchar int", "3 0 2 1\n4 0 1 3\n", 2),
                 "element 'face' item 1 of 2 (line 15) claims 4 entries in its list 'vertex_indices' but its line "
                 "holds only 3");
  EXPECT_REFUSED("missing_lines.ply", asciiPly("uchar int", "3 0 2 1\n", 2),
                 "the PLY body ends before element 'face' item 1 of 2");
  EXPECT_REFUSED("not_a_number.ply", asciiPly("uchar int", "3 0 x 1\n", 1),
                 "element 'face' item 0 of 1 (line 14) has 'x 1' where property 'vertex_indices' needs a number");
  // Debian's assimp-testmodels: the ASCII files with faces still load.
  for (const char* f : {"Wuson.ply", "cube.ply", "cube_uv.ply", "float-color.ply"}) {
    const std::string file = std::string("/usr/share/assimp/models/PLY/") + f;
    if (fs::exists(file)) {
      EXPECT_GT(loadMeshFile(file).triangles.size(), 0u) << file;
    }
  }
}

const std::string kOffTetra = "0 0 0\n1 0 0\n0 1 0\n0 0 1\n";

TEST(MeshFile, OffFacesThatAssimpOnlyLogsAreRefused) {
  const std::string head = "OFF\n4 4 6\n" + kOffTetra;
  EXPECT_EQ(triangles("tetra.off", head + "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n"), 4u);
  // assimp 5.2 puts the last vertex in place of an index out of range.
  EXPECT_REFUSED("index.off", head + "3 0 2 1\n3 0 1 7\n3 0 3 2\n3 1 2 3\n",
                 "face 1 (line 8) uses vertex 7 but the file has 4 (indices start at 0)");
  EXPECT_REFUSED("index_wraps.off", head + "3 0 2 1\n3 0 1 4294967296\n3 0 3 2\n3 1 2 3\n",
                 "face 1 (line 8) uses vertex 4294967296 but the file has 4");
  // ... and drops a face of size 0, a negative one (read as 0) or one above 9, losing the file's
  // last face as well through the count it then keeps.
  EXPECT_REFUSED("negative_size.off", head + "3 0 2 1\n-3 0 1 3\n3 0 3 2\n3 1 2 3\n",
                 "face 1 (line 8) has a negative vertex count");
  EXPECT_REFUSED("zero_size.off", head + "0\n3 0 1 3\n3 0 3 2\n3 1 2 3\n", "face 0 (line 7) has 0 vertices");
  EXPECT_REFUSED("ten.off", head + "3 0 2 1\n3 0 1 3\n3 0 3 2\n10 1 2 3 1 2 3 1 2 3 1\n",
                 "face 3 (line 10) has 10 vertices; assimp 5.2's OFF reader drops faces of more than 9");
  EXPECT_REFUSED("comment_face.off", head + "3 0 2 1\n# a comment\n3 0 1 3\n3 0 3 2\n3 1 2 3\n",
                 "face 1 (line 8) does not start with its vertex count: '# a comment'");
  // A line or a point is not a face (collect() skipped them without a word).
  EXPECT_REFUSED("line.off", head + "3 0 2 1\n2 0 1\n3 0 3 2\n3 1 2 3\n",
                 "face 1 (line 8) has 2 vertices; a face needs at least 3");
  // Fewer indices than the size: assimp reads 0 for the missing ones.
  EXPECT_REFUSED("short.off", head + "3 0 2 1\n3 0 1 3\n4 0 3 2\n3 1 2 3\n", "face 2 (line 9) lists 3 of its 4 vertex indices");
  EXPECT_REFUSED("negative_index.off", head + "3 0 2 1\n3 0 -1 3\n3 0 3 2\n3 1 2 3\n",
                 "face 1 (line 8) has a negative vertex index");
  EXPECT_REFUSED("float_index.off", head + "3 0 2 1\n3 0 1.5 3\n3 0 3 2\n3 1 2 3\n",
                 "face 1 (line 8) has '.5 3' where vertex index 2 should be");
  EXPECT_REFUSED("few_faces.off", head + "3 0 2 1\n3 0 1 3\n", "the header claims 4 faces but the file ends after 2 face lines");
  EXPECT_REFUSED("few_vertices.off", "OFF\n4 1 0\n0 0 0\n1 0 0\n", "the header claims 4 vertices but the file ends after 2");
  // Without "OFF" (allowed by the format, read by extension) the counts are checked too.
  EXPECT_REFUSED("headerless.off", "200000000 1 0\n0 0 0\n", "the header claims 200000000 vertices");
  EXPECT_REFUSED("long_line.off", "OFF\n3 1 0\n0 0 0\n0 1 0" + std::string(5000, ' ') + "\n1 0 0\n3 0 1 2\n",
                 "line 4 has 4096 characters or more");
}

TEST(MeshFile, OffFilesThatAssimpReadsCorrectlyStillLoad) {
  // Comments and blank lines where assimp skips them, vertex colours after COFF, face colours
  // after the indices, quads, CRLF line ends.
  EXPECT_EQ(triangles("coff.off", "# a comment\nCOFF # the header\n\n# counts next\n4 2 0\n"
                                  "0 0 0 255 0 0 255\n1 0 0 0 255 0 255\n\n1 1 0 0 0 255 255\n0 0 1 9 9 9 9\n"
                                  "4 0 1 2 3 0.5 0.5 0.5\n3 0 1 3 1 0 0\n"),
            3u);
  EXPECT_EQ(triangles("noff.off", "NOFF\r\n4 4 6\r\n0 0 0 0 0 1\r\n1 0 0 0 0 1\r\n0 1 0 0 0 1\r\n0 0 1 0 0 1\r\n"
                                  "3 0 2 1\r\n3 0 1 3\r\n3 0 3 2\r\n3\t1\t2\t3"),
            4u);
  EXPECT_EQ(triangles("bom.off", "\xEF\xBB\xBFOFF\n4 4 6\n" + kOffTetra + "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n"), 4u);
  // Without "OFF" (a leading 4 would be taken for the homogeneous prefix: not one that starts so).
  EXPECT_EQ(triangles("headerless.off", "3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"), 1u);
  EXPECT_EQ(triangles("nine.off", "OFF\n9 1 0\n1 0 0\n0.77 0.64 0\n0.17 0.98 0\n-0.5 0.87 0\n-0.94 0.34 0\n"
                                  "-0.94 -0.34 0\n-0.5 -0.87 0\n0.17 -0.98 0\n0.77 -0.64 0\n9 0 1 2 3 4 5 6 7 8\n"),
            7u);
  for (const char* f : {"OFF/Cube.off", "OFF/Wuson.off"}) {
    const std::string file = std::string("/usr/share/assimp/models/") + f;
    if (fs::exists(file)) {
      EXPECT_GT(loadMeshFile(file).triangles.size(), 0u) << file;
    }
  }
}

/// An ASCII STL facet of the given corners.
std::string stlFacet(const std::vector<const char*>& corners) {
  std::string f = "  facet normal 0 0 1\n    outer loop\n";
  for (const char* c : corners) f += std::string("      vertex ") + c + "\n";
  return f + "    endloop\n  endfacet\n";
}

TEST(MeshFile, AsciiStlFacetsNeedExactlyThreeVertices) {
  const std::string a = "0 0 0", b = "1 0 0", c = "0 1 0", d = "1 1 0";
  const std::string two = stlFacet({a.c_str(), b.c_str(), c.c_str()}) + stlFacet({b.c_str(), d.c_str(), c.c_str()});
  EXPECT_EQ(triangles("two.stl", "solid two\n" + two + "endsolid two\n"), 2u);
  // Two solids in one file, and a file named otherwise that assimp takes for STL by its "solid".
  EXPECT_EQ(triangles("solids", "solid a\n" + two + "endsolid a\nsolid b\n" + two + "endsolid b\n"), 4u);
  // A quad: assimp 5.2 kept its first three corners with only a log line (a hole in the mesh).
  EXPECT_REFUSED("quad.stl", "solid q\n" + stlFacet({a.c_str(), b.c_str(), d.c_str(), c.c_str()}) + "endsolid q\n",
                 "STL facet 0 (line 2) has 4 vertices; a facet has exactly 3");
  // Facets of two corners, three of them: six positions, which assimp cut into two triangles made
  // of corners of different facets, without a word.
  const std::string short_facet = stlFacet({a.c_str(), b.c_str()});
  EXPECT_REFUSED("short.stl", "solid s\n" + stlFacet({a.c_str(), b.c_str(), c.c_str()}) + short_facet + short_facet +
                                  short_facet + "endsolid s\n",
                 "STL facet 1 (line 9) has 2 vertices");
  // The last facet, cut off by the end of the file.
  EXPECT_REFUSED("cut.stl", "solid s\n" + two + "  facet normal 0 0 1\n    outer loop\n      vertex 0 0 0\n",
                 "STL facet 2 (line 16) has 1 vertices");
  // A binary STL (its facet count gives the file's size) is not scanned as text.
  std::string binary(84, '\0');
  std::memcpy(binary.data(), "solid but binary", 16);
  const std::uint32_t facets = 1;
  std::memcpy(binary.data() + 80, &facets, 4);
  const float facet[12] = {0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0};
  binary.append(reinterpret_cast<const char*>(facet), sizeof facet);
  binary.append(2, '\0');
  EXPECT_EQ(triangles("binary.stl", binary), 1u);
}

}  // namespace
}  // namespace psc::demo
