#include "mesh_file.h"

#include "psc/error.h"

#include <assimp/Importer.hpp>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <new>
#include <sstream>
#include <string_view>
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

/// The whole file, for the body scans below (assimp reads it whole as well).
std::string readFile(const std::string& path, std::uintmax_t size) {
  std::ifstream in(path, std::ios::binary);
  std::string data(static_cast<std::size_t>(size), '\0');
  in.read(data.data(), static_cast<std::streamsize>(data.size()));
  data.resize(static_cast<std::size_t>(in.gcount()));
  return data;
}

bool isDigit(char c) { return c >= '0' && c <= '9'; }
// assimp's ParsingUtils: a line ends at CR, LF, NUL or form feed; spaces are blanks and tabs.
bool isLineEnd(char c) { return c == '\r' || c == '\n' || c == '\0' || c == '\f'; }
bool isBlank(char c) { return c == ' ' || c == '\t'; }

/// assimp's strtoul10 on the digits at `p` (none: 0), which wraps at 2^32 like assimp's.
std::uint32_t readDigits(const std::string_view s, std::size_t& p) {
  std::uint32_t v = 0;
  for (; p < s.size() && isDigit(s[p]); ++p) v = v * 10u + static_cast<std::uint32_t>(s[p] - '0');
  return v;
}

/// The same digits as an exact count, saturating far above any file size.
std::uint64_t readCount(const std::string_view s, std::size_t& p) {
  std::uint64_t v = 0;
  for (; p < s.size() && isDigit(s[p]); ++p) v = std::min<std::uint64_t>(v * 10u + static_cast<std::uint64_t>(s[p] - '0'), 1ull << 60);
  return v;
}

/// 1-based line number of byte `at`, for messages (counted only when one is thrown).
std::size_t lineOf(const std::string& data, std::size_t at) {
  return 1 + static_cast<std::size_t>(std::count(data.begin(), data.begin() + static_cast<std::ptrdiff_t>(std::min(at, data.size())), '\n'));
}

/// A short printable quote of a line for messages.
std::string quote(std::string_view text) {
  std::string out;
  for (char c : text.substr(0, 40)) out += (c >= 32 && c < 127) ? c : '?';
  return "'" + out + (text.size() > 40 ? "...'" : "'");
}

// ---- PLY ------------------------------------------------------------------------------------
// assimp 5.2's PLY reader (code/AssetLib/Ply/PlyParser.cpp) believes every list length it reads:
// it resizes the list to it before reading a single entry, so one binary face whose uint length
// says 4e9 asks for 32 GB (a 170-byte file asked for 2.7 GB, stop 46), and in ASCII a face line
// "-1 0 1 2" with an int length does the same. The scan below reads the header as assimp does
// (which lines end an element's properties, which counts it takes) and walks the body with
// assimp's offsets, so that every list assimp will allocate is checked against what the file
// holds before assimp sees it.

enum class PlyType { Invalid, Char, UChar, Short, UShort, Int, UInt, Float, Double };

PlyType plyType(std::string_view word) {
  // assimp's names (PLY::Property::ParseDataType); an unknown type ends the element's properties.
  if (word == "char" || word == "int8") return PlyType::Char;
  if (word == "uchar" || word == "uint8") return PlyType::UChar;
  if (word == "short" || word == "int16") return PlyType::Short;
  if (word == "ushort" || word == "uint16") return PlyType::UShort;
  if (word == "int32" || word == "int") return PlyType::Int;
  if (word == "uint32" || word == "uint") return PlyType::UInt;
  if (word == "float" || word == "float32") return PlyType::Float;
  if (word == "double64" || word == "double" || word == "float64") return PlyType::Double;
  return PlyType::Invalid;
}

std::size_t plySize(PlyType t) {
  switch (t) {
    case PlyType::Char: case PlyType::UChar: return 1;
    case PlyType::Short: case PlyType::UShort: return 2;
    case PlyType::Int: case PlyType::UInt: case PlyType::Float: return 4;
    case PlyType::Double: return 8;
    case PlyType::Invalid: break;
  }
  return 0;
}

bool plySigned(PlyType t) { return t == PlyType::Char || t == PlyType::Short || t == PlyType::Int; }
bool plyReal(PlyType t) { return t == PlyType::Float || t == PlyType::Double; }

struct PlyProperty {
  std::string name;
  bool list = false;
  PlyType count_type = PlyType::Invalid;  ///< lists only
  PlyType type = PlyType::Invalid;
};

struct PlyElement {
  std::string name;
  std::uint64_t count = 0;  ///< as assimp reads it
  bool parsed = false;      ///< assimp reads its values (else, in ASCII, it skips a line per item)
  std::vector<PlyProperty> properties;
};

/// assimp's IOStreamBuffer::getNextLine: a line end first skips to the next LF (so one blank line
/// between two lines is skipped, a second one is a line of its own); the line runs to the next
/// CR, LF, NUL or form feed.
struct PlyLines {
  const std::string& data;
  std::size_t pos = 0;
  bool next(std::string_view& line, std::size_t& start) {
    const std::size_t n = data.size();
    if (pos >= n) return false;
    if (isLineEnd(data[pos])) {
      while (pos < n && data[pos] != '\n') ++pos;
      if (++pos >= n) return false;
    }
    start = pos;
    while (pos < n && !isLineEnd(data[pos])) ++pos;
    line = std::string_view(data).substr(start, pos - start);
    ++pos;
    return true;
  }
};

std::vector<std::string_view> words(std::string_view line) {
  std::vector<std::string_view> out;
  for (std::size_t p = 0; p < line.size();) {
    while (p < line.size() && isBlank(line[p])) ++p;
    const std::size_t b = p;
    while (p < line.size() && !isBlank(line[p])) ++p;
    if (p > b) out.push_back(line.substr(b, p - b));
  }
  return out;
}

/// Consumes one ASCII value of type `t` at `p` as assimp's PLY::PropertyInstance::ParseValue does
/// (strtoul10, strtol10 or fast_atoreal_move: a number's prefix, not a whole word). Returns false
/// where assimp would read nothing (and so take a 0 and read the same text again) or throw.
bool plyAsciiValue(std::string_view s, std::size_t& p, PlyType t, double* value) {
  const std::size_t begin = p;
  const auto at = [&](std::size_t i) { return i < s.size() ? s[i] : '\0'; };
  bool negative = false;
  if (!plyReal(t)) {
    if (plySigned(t) && (at(p) == '-' || at(p) == '+')) negative = s[p++] == '-';
    const std::size_t d = p;
    const std::uint64_t v = readCount(s, p);
    if (p == d) return false;
    if (value) *value = negative ? -static_cast<double>(v) : static_cast<double>(v);
    return true;
  }
  if (at(p) == '-' || at(p) == '+') ++p;
  const auto word = [&](const char* w) {
    for (std::size_t k = 0; w[k]; ++k)
      if (std::tolower(static_cast<unsigned char>(at(p + k))) != w[k]) return false;
    return true;
  };
  if (word("nan") || word("inf")) {
    p += word("infinity") ? 8 : 3;
    if (value) *value = std::nan("");  // never a count: a NaN or infinite length is refused
    return true;
  }
  const bool point = (at(p) == '.' || at(p) == ',') && isDigit(at(p + 1));
  if (!isDigit(at(p)) && !point) return false;
  std::size_t d = p;
  while (isDigit(at(p))) ++p;
  if (p - d > 19) return false;  // assimp's strtoul10_64 overflows and stops there
  if ((at(p) == '.' || at(p) == ',') && isDigit(at(p + 1))) {
    for (++p; isDigit(at(p));) ++p;
  } else if (at(p) == '.') {
    ++p;
  }
  if (at(p) == 'e' || at(p) == 'E') {
    ++p;
    if (at(p) == '-' || at(p) == '+') ++p;
    d = p;
    while (isDigit(at(p))) ++p;
    if (p == d || p - d > 19) return false;
  }
  if (value) {
    std::string text(s.substr(begin, p - begin));
    for (char& c : text)
      if (c == ',') c = '.';
    *value = std::strtod(text.c_str(), nullptr);
  }
  return true;
}

/// A length read from the file, for messages: whole numbers without a fraction.
std::string number(double v) {
  if (std::isfinite(v) && v == std::floor(v) && std::fabs(v) < 1e18) return std::to_string(static_cast<long long>(v));
  std::ostringstream out;
  out << v;
  return out.str();
}

/// A list length as assimp converts it (ConvertTo<unsigned int>), or an error for one it would
/// turn into a huge count: a negative, NaN or infinite length.
bool plyListLength(double v, std::uint64_t& n) {
  if (!(v >= 0.0) || !std::isfinite(v)) return false;
  n = static_cast<std::uint64_t>(std::min(v, 1e18));
  return true;
}

void checkPlyBody(const std::string& path, const std::string& data) {
  PlyLines lines{data};
  std::string_view line;
  std::size_t start = 0;
  // First line "ply", second "format ...": assimp throws itself on anything else.
  if (!lines.next(line, start) || line.size() < 3 || std::tolower(static_cast<unsigned char>(line[0])) != 'p' ||
      std::tolower(static_cast<unsigned char>(line[1])) != 'l' || std::tolower(static_cast<unsigned char>(line[2])) != 'y')
    return;
  if (!lines.next(line, start)) return;
  std::size_t f = 0;
  while (f < line.size() && isBlank(line[f])) ++f;
  const std::vector<std::string_view> format = words(line.substr(f));
  if (format.size() < 2 || format[0] != "format") return;
  const bool binary = format[1].substr(0, 7) == "binary_";
  if (!binary && format[1] != "ascii") return;
  // As assimp decides: any "binary_" but "binary_b..." is little-endian.
  const bool big_endian = binary && format[1].size() > 7 && (format[1][7] == 'b' || format[1][7] == 'B');

  // The header as PLY::DOM::ParseHeader reads it. An element's properties run to the first line
  // that is not a property (a comment or a blank line ends them too: later "property" lines are
  // then ignored); a property of an unknown type ends them as well. An element whose name assimp
  // does not know gets the count of the digits its name starts with (usually 0).
  std::vector<PlyElement> elements;
  bool in_properties = false;
  for (;;) {
    if (!lines.next(line, start)) return;  // no end_header: checkPlyHeader has thrown already
    const std::vector<std::string_view> w = words(line);
    const bool comment = !w.empty() && w[0] == "comment";
    const bool texture_file = comment && w.size() > 1 && w[1] == "TextureFile";
    if (in_properties) {
      if (!w.empty() && w[0] == "property") {
        PlyProperty p;
        std::size_t k = 1;
        if (w.size() > k && w[k] == "list") {
          p.list = true;
          ++k;
          p.count_type = w.size() > k ? plyType(w[k++]) : PlyType::Invalid;
        }
        p.type = w.size() > k ? plyType(w[k++]) : PlyType::Invalid;
        if ((p.list && p.count_type == PlyType::Invalid) || p.type == PlyType::Invalid) {
          in_properties = false;  // assimp skips the line and takes no more properties
          continue;
        }
        // Without a name assimp reads past the line's end into what its buffer held before.
        if (w.size() <= k)
          throw fileError(path, "the PLY header's line " + std::to_string(lineOf(data, start)) + " " + quote(line) +
                                    " declares a property without a name");
        p.name = std::string(w[k]);
        elements.back().properties.push_back(std::move(p));
        continue;
      }
      in_properties = false;
      if (!texture_file && (comment || w.empty())) continue;
    }
    if (!w.empty() && w[0] == "end_header") break;
    if (w.empty() || (w[0] != "element" && !texture_file)) continue;  // comments, obj_info, other lines
    if (texture_file) {
      elements.push_back(PlyElement{"TextureFile", 0, false, {}});
      continue;
    }
    if (w.size() < 2)
      throw fileError(path, "the PLY header's line " + std::to_string(lineOf(data, start)) + " " + quote(line) +
                                " declares an element without a name");
    PlyElement e;
    e.name = std::string(w[1]);
    static const char* const kKnown[] = {"vertex", "face", "tristrips", "edge", "material"};
    const bool known = std::find(std::begin(kKnown), std::end(kKnown), e.name) != std::end(kKnown);
    if (e.name == "TextureFile") {
      elements.push_back(std::move(e));
      continue;
    }
    std::size_t p = 0;
    if (known) {
      if (w.size() < 3)
        throw fileError(path, "the PLY header's line " + std::to_string(lineOf(data, start)) + " " + quote(line) +
                                  " declares an element without a count");
      e.count = readDigits(w[2], p);
    } else {
      e.count = readDigits(w[1], p);
    }
    e.parsed = known;
    elements.push_back(std::move(e));
    in_properties = true;
  }
  for (PlyElement& e : elements) e.parsed = e.parsed && !e.properties.empty();

  // Every item of every element takes at least a byte (a line in ASCII): more items than bytes
  // would have assimp allocate for items the file cannot hold (elements without properties take
  // no bytes in a binary body, so their counts are bounded here and nowhere else).
  std::uint64_t items = 0;
  for (const PlyElement& e : elements) items += e.count;
  if (items > data.size())
    throw fileError(path, "the PLY header's elements claim " + std::to_string(items) + " items in all but the file has only " +
                              std::to_string(data.size()) + " bytes");

  if (binary) {
    // The body starts after end_header's line end (and an LF after a CR), as assimp takes it.
    std::size_t at = lines.pos;
    if (at < data.size() && data[at] == '\n') ++at;
    const std::size_t n = data.size();
    for (const PlyElement& e : elements) {
      const bool fixed = std::none_of(e.properties.begin(), e.properties.end(), [](const PlyProperty& p) { return p.list; });
      if (fixed) {
        // No lists: the whole element at once.
        std::uint64_t stride = 0;
        for (const PlyProperty& p : e.properties) stride += plySize(p.type);
        if (stride == 0) continue;
        const std::uint64_t left = n - std::min(at, n);
        if (e.count * stride > left)
          throw fileError(path, "the binary PLY body ends inside element '" + e.name + "' item " +
                                    std::to_string(left / stride) + " of " + std::to_string(e.count) + " (" +
                                    std::to_string(stride) + " bytes each, " + std::to_string(left) +
                                    " bytes left for the element)");
        at += static_cast<std::size_t>(e.count * stride);
        continue;
      }
      for (std::uint64_t i = 0; i < e.count; ++i)
        for (const PlyProperty& p : e.properties) {
          const std::size_t left = n - std::min(at, n);
          const std::size_t size = plySize(p.list ? p.count_type : p.type);
          if (size > left)
            throw fileError(path, "the binary PLY body ends inside element '" + e.name + "' item " + std::to_string(i) +
                                      " of " + std::to_string(e.count) + " (property '" + p.name + "' needs " +
                                      std::to_string(size) + " bytes, " + std::to_string(left) + " are left)");
          if (!p.list) {
            at += size;
            continue;
          }
          unsigned char b[8];
          std::memcpy(b, data.data() + at, size);
          if (big_endian) std::reverse(b, b + size);
          double v = 0.0;
          switch (p.count_type) {
            case PlyType::Char: v = static_cast<std::int8_t>(b[0]); break;
            case PlyType::UChar: v = b[0]; break;
            case PlyType::Short: { std::int16_t x; std::memcpy(&x, b, 2); v = x; break; }
            case PlyType::UShort: { std::uint16_t x; std::memcpy(&x, b, 2); v = x; break; }
            case PlyType::Int: { std::int32_t x; std::memcpy(&x, b, 4); v = x; break; }
            case PlyType::UInt: { std::uint32_t x; std::memcpy(&x, b, 4); v = x; break; }
            case PlyType::Float: { float x; std::memcpy(&x, b, 4); v = static_cast<double>(x); break; }
            case PlyType::Double: std::memcpy(&v, b, 8); break;
            case PlyType::Invalid: break;
          }
          std::uint64_t length = 0;
          if (!plyListLength(v, length))
            throw fileError(path, "element '" + e.name + "' item " + std::to_string(i) + " of " + std::to_string(e.count) +
                                      " gives its list '" + p.name + "' the length " + number(v) +
                                      " (assimp would read it as about 4e9 entries)");
          at += size;
          const std::uint64_t need = length * plySize(p.type);
          if (need > n - at)
            throw fileError(path, "element '" + e.name + "' item " + std::to_string(i) + " of " + std::to_string(e.count) +
                                      " claims " + std::to_string(length) + " entries in its list '" + p.name + "' (" +
                                      std::to_string(need) + " bytes) but only " + std::to_string(n - at) +
                                      " bytes of the file are left");
          at += static_cast<std::size_t>(need);
        }
    }
    return;
  }

  // ASCII: an item is a line (PLY::ElementInstanceList::ParseInstanceList); values are read as
  // number prefixes, and a list is resized to its length before its entries are read.
  for (const PlyElement& e : elements)
    for (std::uint64_t i = 0; i < e.count; ++i) {
      if (!lines.next(line, start))
        throw fileError(path, "the PLY body ends before element '" + e.name + "' item " + std::to_string(i) + " of " +
                                  std::to_string(e.count));
      if (!e.parsed) continue;
      std::size_t p = 0;
      const auto where = [&] {
        return "element '" + e.name + "' item " + std::to_string(i) + " of " + std::to_string(e.count) + " (line " +
               std::to_string(lineOf(data, start)) + ")";
      };
      const auto value = [&](PlyType t, const PlyProperty& prop, double* v) {
        while (p < line.size() && isBlank(line[p])) ++p;
        if (p >= line.size())
          throw fileError(path, where() + " ends before the values of its property '" + prop.name + "'");
        if (!plyAsciiValue(line, p, t, v))
          throw fileError(path, where() + " has " + quote(line.substr(p)) + " where property '" + prop.name +
                                    "' needs a number");
      };
      for (const PlyProperty& prop : e.properties) {
        if (!prop.list) {
          value(prop.type, prop, nullptr);
          continue;
        }
        double v = 0.0;
        value(prop.count_type, prop, &v);
        std::uint64_t length = 0;
        if (!plyListLength(v, length))
          throw fileError(path, where() + " gives its list '" + prop.name + "' the length " + number(v) +
                                    " (assimp would read it as about 4e9 entries)");
        for (std::uint64_t k = 0; k < length; ++k) {
          while (p < line.size() && isBlank(line[p])) ++p;
          if (p >= line.size())
            throw fileError(path, where() + " claims " + std::to_string(length) + " entries in its list '" + prop.name +
                                      "' but its line holds only " + std::to_string(k));
          value(prop.type, prop, nullptr);
        }
      }
    }
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

// ---- OFF ------------------------------------------------------------------------------------
// assimp 5.2's OFF reader (code/AssetLib/OFF/OFFLoader.cpp) only logs what is wrong in a face: an
// index past the vertices becomes the last vertex, a size of 0, a negative one (read as 0) or one
// above 9 drops the face (and with it, through a count it then gets wrong, the file's last face),
// a face of 1 or 2 vertices is a point or a line that collect() would skip. So the body is read
// here as assimp reads it: the counts after the optional prefixes (ST, C, N, 4, n) and "OFF",
// skipping blanks and "#" comment lines; then a line per vertex and a line per face, a line
// running to CR, LF, NUL or form feed, blank lines skipped. Vertex lines are left to assimp, which
// throws on one that does not start with a number. A face line is its size, then that many
// indices; anything after them (colours) is ignored, as assimp does.

/// `body` false: the file is not read as OFF by assimp (another extension, no "off" at its start),
/// and only the counts are checked, as they were before the body scan.
void checkOff(const std::string& path, std::string data, bool body) {
  if (data.size() >= 2 && ((data[0] == '\xFF' && data[1] == '\xFE') || (data[0] == '\xFE' && data[1] == '\xFF')))
    return;  // UTF-16 or UTF-32: assimp converts it first; left to assimp
  std::size_t bom = 0;
  if (data.compare(0, 3, "\xEF\xBB\xBF") == 0) bom = 3;  // assimp drops a UTF-8 byte order mark
  data.push_back('\0');  // assimp's buffer ends in a NUL; every read below stops at it
  const std::string_view d = std::string_view(data).substr(bom);
  const std::size_t end = d.size();
  const std::uintmax_t size = data.size() - 1;
  std::size_t c = 0;
  const auto skipSpacesAndLineEnds = [&] {
    while (d[c] == ' ' || d[c] == '\t' || d[c] == '\r' || d[c] == '\n') ++c;
  };
  const auto nextToken = [&] {
    skipSpacesAndLineEnds();
    while (c < end && (d[c] == '#' || d[c] == '\n' || d[c] == '\r')) {
      while (d[c] != '\r' && d[c] != '\n' && d[c] != '\0') ++c;
      while (d[c] == '\r' || d[c] == '\n') ++c;
      skipSpacesAndLineEnds();
    }
  };
  const auto token = [&](std::size_t at) {
    std::size_t e = at;
    while (e < end && !isBlank(d[e]) && !isLineEnd(d[e])) ++e;
    return std::string(d.substr(at, e - at));
  };
  nextToken();
  if (c + 2 < end && d[c] == 'S' && d[c + 1] == 'T') c += 2;
  if (c + 1 < end && d[c] == 'C') ++c;
  if (c + 1 < end && d[c] == 'N') ++c;
  if (c + 1 < end && d[c] == '4') ++c;
  bool dimension = false;
  if (c + 1 < end && d[c] == 'n') {
    dimension = true;
    ++c;
  }
  if (c + 3 < end && d.compare(c, 3, "OFF") == 0) {
    c += 3;
    nextToken();
  } else {
    nextToken();
    if (c + 1 >= end || !isDigit(d[c])) return;  // assimp: "OFF: Header is invalid"
  }
  if (dimension) {
    if (readDigits(d, c) > 3) return;  // assimp: more than 3 coordinates unsupported
    nextToken();
  }
  nextToken();
  const std::string vertices_token = token(c);
  const std::uint32_t vertices = readDigits(d, c);
  nextToken();
  const std::string faces_token = token(c);
  const std::uint32_t faces = readDigits(d, c);
  nextToken();
  readDigits(d, c);  // edges
  nextToken();
  checkCount(path, size, "vertices", vertices_token);
  checkCount(path, size, "faces", faces_token);
  if (!body || vertices == 0 || faces == 0) return;  // assimp throws on a zero count

  // assimp's GetNextLine copies a line into a 4096-byte buffer and writes its terminator one past
  // the end when the line fills it; a longer line goes on as the next one.
  const auto nextLine = [&](std::size_t& b, std::string_view& line, std::size_t& at) {
    if (d[b] == '\0') return false;
    at = b;
    while (!isLineEnd(d[b]) && b - at < 4096) ++b;
    if (b - at >= 4096)
      throw fileError(path, "line " + std::to_string(lineOf(data, bom + at)) +
                                " has 4096 characters or more, more than assimp's OFF reader takes");
    line = d.substr(at, b - at);
    while (isLineEnd(d[b]) && d[b] != '\0') ++b;
    return true;
  };
  std::size_t b = c, at = 0;
  std::string_view line;
  for (std::uint32_t v = 0; v < vertices; ++v)
    if (!nextLine(b, line, at))
      throw fileError(path, "the header claims " + std::to_string(vertices) + " vertices but the file ends after " +
                                std::to_string(v) + " vertex lines");
  for (std::uint32_t f = 0; f < faces; ++f) {
    if (!nextLine(b, line, at))
      throw fileError(path, "the header claims " + std::to_string(faces) + " faces but the file ends after " +
                                std::to_string(f) + " face lines");
    // Named only when one is thrown: counting the lines up to every face would be quadratic.
    const auto face = [&] { return "face " + std::to_string(f) + " (line " + std::to_string(lineOf(data, bom + at)) + ")"; };
    std::size_t p = 0;
    while (p < line.size() && isBlank(line[p])) ++p;
    if (p < line.size() && line[p] == '-')
      throw fileError(path, face() + " has a negative vertex count: " + quote(line));
    if (p >= line.size() || !isDigit(line[p]))
      throw fileError(path, face() + " does not start with its vertex count: " + quote(line));
    const std::uint64_t n = readCount(line, p);
    if (n < 3)
      throw fileError(path, face() + " has " + std::to_string(n) + " vertices; a face needs at least 3");
    if (n > 9)
      throw fileError(path, face() + " has " + std::to_string(n) +
                                " vertices; assimp 5.2's OFF reader drops faces of more than 9");
    for (std::uint64_t k = 0; k < n; ++k) {
      while (p < line.size() && isBlank(line[p])) ++p;
      if (p >= line.size())
        throw fileError(path, face() + " lists " + std::to_string(k) + " of its " + std::to_string(n) + " vertex indices");
      if (line[p] == '-') throw fileError(path, face() + " has a negative vertex index: " + quote(line));
      if (!isDigit(line[p]))
        throw fileError(path, face() + " has " + quote(line.substr(p)) + " where vertex index " + std::to_string(k) +
                                  " should be");
      const std::uint64_t index = readCount(line, p);
      if (index >= vertices)
        throw fileError(path, face() + " uses vertex " + std::to_string(index) + " but the file has " +
                                  std::to_string(vertices) + " (indices start at 0)");
    }
  }
}

// ---- STL ------------------------------------------------------------------------------------
// assimp 5.2's ASCII STL reader (LoadASCIIFile) takes the positions of its "vertex" lines in order
// and cuts them into triangles by threes: a facet with a fourth vertex loses it with only a log
// line (a quad becomes a triangle and leaves a hole), and a facet with fewer than three shifts
// every later triangle onto the next facet's corners (only a total that is not a multiple of three
// fails). Every facet must have exactly three vertices.

/// Whether assimp reads the file as a binary STL (IsBinarySTL: the facet count at byte 80 gives
/// the file's size exactly, in 32-bit arithmetic as there).
bool binaryStl(const std::string& data) {
  if (data.size() < 84) return false;
  std::uint32_t facets = 0;
  std::memcpy(&facets, data.data() + 80, 4);
  return static_cast<std::uint32_t>(facets * 50u + 84u) == data.size();
}

void checkAsciiStl(const std::string& path, const std::string& data) {
  if (binaryStl(data)) return;
  // assimp's tokens: words between blanks and line ends; "facet" opens a facet, "vertex" adds a
  // corner to it (before any facet assimp skips it), "endsolid" ends the solid.
  const auto space = [](char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\f' || c == '\0'; };
  std::size_t facet = 0, corners = 3, facet_at = 0;
  bool open = false;
  const auto close = [&] {
    if (open && corners != 3)
      throw fileError(path, "STL facet " + std::to_string(facet - 1) + " (line " + std::to_string(lineOf(data, facet_at)) +
                                ") has " + std::to_string(corners) + " vertices; a facet has exactly 3");
    open = false;
  };
  for (std::size_t p = 0; p < data.size();) {
    while (p < data.size() && space(data[p])) ++p;
    const std::size_t b = p;
    while (p < data.size() && !space(data[p])) ++p;
    const std::string_view w = std::string_view(data).substr(b, p - b);
    if (w == "facet") {
      close();
      open = true;
      corners = 0;
      facet_at = b;
      ++facet;
    } else if (w == "vertex") {
      if (open) ++corners;
    } else if (w.substr(0, 8) == "endsolid") {
      close();
    }
  }
  close();
}

/// Headers are checked before assimp reads the file: OFF and PLY element counts must fit the file,
/// a PLY header must end (see checkPlyHeader), and the bodies are scanned for what assimp 5.2 would
/// allocate too much for (PLY lists) or load wrongly without failing (OFF faces, ASCII STL facets).
void checkHeader(const std::string& path, std::uintmax_t size) {
  std::ifstream in(path, std::ios::binary);
  std::string head(kHeaderBytes, '\0');
  in.read(head.data(), static_cast<std::streamsize>(head.size()));
  head.resize(static_cast<std::size_t>(in.gcount()));
  std::istringstream text(head);
  std::string first;
  std::getline(text, first);
  // assimp reads a file as PLY by its extension, or by a "ply" at its start whatever follows
  // (in any case: its magic check takes "PLY" too).
  std::string ext = std::filesystem::path(path).extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  std::string start = head.substr(0, 3);
  for (char& c : start) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (ext == ".ply" || start == "ply") {
    checkPlyHeader(path, size, text);
    return checkPlyBody(path, readFile(path, size));
  }
  // assimp reads a file as OFF by its extension, or by an "off" in its first 3 bytes (any case).
  std::istringstream words(first);
  words >> first;
  const bool off_word = first.size() >= 3 && first.compare(first.size() - 3, 3, "OFF") == 0;
  if (ext == ".off" || start == "off" || off_word) return checkOff(path, readFile(path, size), ext == ".off" || start == "off");
  // assimp reads a file as STL by its extension, or by a "solid" or "STL" near its start.
  std::size_t lead = 0;
  while (lead < head.size() && std::isspace(static_cast<unsigned char>(head[lead]))) ++lead;
  if (ext == ".stl" || head.compare(lead, 5, "solid") == 0) checkAsciiStl(path, readFile(path, size));
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
