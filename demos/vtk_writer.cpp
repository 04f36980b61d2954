#include "vtk_writer.h"

#include "psc/error.h"

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <sstream>

namespace psc::demo {
namespace {

std::ofstream openOut(const std::string& path) {
  std::ofstream out(path);
  if (!out) throw Error(ErrorCode::FileError, "cannot write '" + path + "'");
  out << std::setprecision(7);
  return out;
}

template <class T, class F>
void dataArray(std::ostream& out, const char* type, const char* name, int components, std::size_t n, F&& value) {
  out << "<DataArray type=\"" << type << "\" Name=\"" << name << "\" NumberOfComponents=\"" << components
      << "\" format=\"ascii\">\n";
  for (std::size_t i = 0; i < n; ++i) {
    out << static_cast<T>(value(i)) << (i % 12 == 11 ? '\n' : ' ');
  }
  out << "\n</DataArray>\n";
}

void writePvd(const std::string& path, const std::vector<std::pair<double, std::string>>& entries) {
  std::ofstream out = openOut(path);
  out << "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\">\n<Collection>\n";
  for (const auto& [t, file] : entries)
    out << "<DataSet timestep=\"" << t << "\" part=\"0\" file=\"" << file << "\"/>\n";
  out << "</Collection>\n</VTKFile>\n";
}

std::string frameName(const std::string& run, const char* kind, std::size_t step) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%06zu", step);
  return run + "/" + kind + "_" + buf + ".vtp";
}

}  // namespace

FrameSeries::FrameSeries(const std::string& dir, const std::string& run_name) : dir_(dir), name_(run_name) {
  std::error_code ec;
  std::filesystem::create_directories(std::filesystem::path(dir) / run_name, ec);
  if (ec) throw Error(ErrorCode::FileError, "cannot create frames directory '" + dir + "/" + run_name + "': " + ec.message());
  surface_pvd_ = dir + "/" + run_name + "_surface.pvd";
  particles_pvd_ = dir + "/" + run_name + "_particles.pvd";
}

void FrameSeries::writeStatic(const std::vector<std::pair<Vec3, Vec3>>& boxes) {
  std::ofstream out = openOut(dir_ + "/" + name_ + "_static.vtp");
  const std::size_t np = 8 * boxes.size(), nf = 6 * boxes.size();
  out << "<?xml version=\"1.0\"?>\n<VTKFile type=\"PolyData\" version=\"0.1\" byte_order=\"LittleEndian\">\n"
      << "<PolyData>\n<Piece NumberOfPoints=\"" << np << "\" NumberOfVerts=\"0\" NumberOfLines=\"0\" NumberOfStrips=\"0\" NumberOfPolys=\""
      << nf << "\">\n<Points>\n<DataArray type=\"Float32\" NumberOfComponents=\"3\" format=\"ascii\">\n";
  for (const auto& [c, h] : boxes)
    for (int k = 0; k < 8; ++k)
      out << c.x() + ((k & 1) ? h.x() : -h.x()) << ' ' << c.y() + ((k & 2) ? h.y() : -h.y()) << ' '
          << c.z() + ((k & 4) ? h.z() : -h.z()) << '\n';
  out << "</DataArray>\n</Points>\n<Polys>\n<DataArray type=\"Int32\" Name=\"connectivity\" format=\"ascii\">\n";
  static const int quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (std::size_t b = 0; b < boxes.size(); ++b)
    for (const auto& q : quads) out << 8 * b + q[0] << ' ' << 8 * b + q[1] << ' ' << 8 * b + q[2] << ' ' << 8 * b + q[3] << '\n';
  out << "</DataArray>\n<DataArray type=\"Int32\" Name=\"offsets\" format=\"ascii\">\n";
  for (std::size_t f = 1; f <= nf; ++f) out << 4 * f << ' ';
  out << "\n</DataArray>\n</Polys>\n</Piece>\n</PolyData>\n</VTKFile>\n";
}

void FrameSeries::writeFrame(std::size_t step, double time, const std::vector<FrameBody>& bodies,
                             const std::vector<FrameParticle>& particles) {
  // Surfaces: all bodies in one piece, with the body id as an attribute (one file per frame keeps
  // the series small in file count; ParaView's Threshold on "body" splits them again).
  std::size_t np = 0, nf = 0;
  for (const FrameBody& b : bodies) {
    np += b.x.size();
    nf += b.triangles->size();
  }
  const std::string surface = frameName(name_, "surface", step);
  {
    std::ofstream out = openOut(dir_ + "/" + surface);
    out << "<?xml version=\"1.0\"?>\n<VTKFile type=\"PolyData\" version=\"0.1\" byte_order=\"LittleEndian\">\n"
        << "<PolyData>\n<Piece NumberOfPoints=\"" << np
        << "\" NumberOfVerts=\"0\" NumberOfLines=\"0\" NumberOfStrips=\"0\" NumberOfPolys=\"" << nf << "\">\n";
    out << "<PointData Scalars=\"region\">\n";
    const auto perVertex = [&](const char* type, const char* name, auto get) {
      out << "<DataArray type=\"" << type << "\" Name=\"" << name << "\" format=\"ascii\">\n";
      for (std::size_t b = 0; b < bodies.size(); ++b)
        for (std::size_t v = 0; v < bodies[b].x.size(); ++v) out << get(b, v) << ' ';
      out << "\n</DataArray>\n";
    };
    perVertex("Int32", "body", [](std::size_t b, std::size_t) { return static_cast<int>(b); });
    perVertex("Int32", "region", [&](std::size_t b, std::size_t v) { return bodies[b].region.empty() ? -1 : bodies[b].region[v]; });
    const auto flag = [&](const std::vector<char> FrameBody::*member) {
      return [&bodies, member](std::size_t b, std::size_t v) {
        const auto& f = bodies[b].*member;
        return f.empty() ? 0 : static_cast<int>(f[v]);
      };
    };
    perVertex("UInt8", "flagged", flag(&FrameBody::flagged));
    perVertex("UInt8", "contact", flag(&FrameBody::contact));
    perVertex("UInt8", "self_contact", flag(&FrameBody::self_contact));
    perVertex("UInt8", "missed", flag(&FrameBody::missed));
    out << "</PointData>\n<CellData Scalars=\"body\">\n<DataArray type=\"Int32\" Name=\"body\" format=\"ascii\">\n";
    for (std::size_t b = 0; b < bodies.size(); ++b)
      for (std::size_t t = 0; t < bodies[b].triangles->size(); ++t) out << b << ' ';
    out << "\n</DataArray>\n<DataArray type=\"UInt8\" Name=\"flagged\" format=\"ascii\">\n";
    for (const FrameBody& b : bodies)
      for (const Triangle& t : *b.triangles)
        out << (!b.flagged.empty() && (b.flagged[t[0]] || b.flagged[t[1]] || b.flagged[t[2]]) ? 1 : 0) << ' ';
    out << "\n</DataArray>\n</CellData>\n<Points>\n<DataArray type=\"Float32\" NumberOfComponents=\"3\" format=\"ascii\">\n";
    for (const FrameBody& b : bodies)
      for (const Vec3& p : b.x) out << p.x() << ' ' << p.y() << ' ' << p.z() << '\n';
    out << "</DataArray>\n</Points>\n<Polys>\n<DataArray type=\"Int32\" Name=\"connectivity\" format=\"ascii\">\n";
    std::size_t base = 0;
    for (const FrameBody& b : bodies) {
      for (const Triangle& t : *b.triangles) out << base + t[0] << ' ' << base + t[1] << ' ' << base + t[2] << '\n';
      base += b.x.size();
    }
    out << "</DataArray>\n<DataArray type=\"Int32\" Name=\"offsets\" format=\"ascii\">\n";
    for (std::size_t f = 1; f <= nf; ++f) out << 3 * f << (f % 16 == 0 ? '\n' : ' ');
    out << "\n</DataArray>\n</Polys>\n</Piece>\n</PolyData>\n</VTKFile>\n";
    if (!out) throw Error(ErrorCode::FileError, "writing '" + dir_ + "/" + surface + "' failed");
  }
  surface_.emplace_back(time, surface);

  const std::string parts = frameName(name_, "particles", step);
  {
    std::ofstream out = openOut(dir_ + "/" + parts);
    const std::size_t n = particles.size();
    out << "<?xml version=\"1.0\"?>\n<VTKFile type=\"PolyData\" version=\"0.1\" byte_order=\"LittleEndian\">\n"
        << "<PolyData>\n<Piece NumberOfPoints=\"" << n << "\" NumberOfVerts=\"" << n
        << "\" NumberOfLines=\"0\" NumberOfStrips=\"0\" NumberOfPolys=\"0\">\n<PointData Scalars=\"body\">\n";
    dataArray<int>(out, "Int32", "body", 1, n, [&](std::size_t i) { return particles[i].body; });
    dataArray<int>(out, "Int32", "region", 1, n, [&](std::size_t i) { return particles[i].region; });
    dataArray<int>(out, "UInt8", "flagged", 1, n, [&](std::size_t i) { return particles[i].flagged ? 1 : 0; });
    out << "</PointData>\n<Points>\n<DataArray type=\"Float32\" NumberOfComponents=\"3\" format=\"ascii\">\n";
    for (const FrameParticle& p : particles) out << p.x.x() << ' ' << p.x.y() << ' ' << p.x.z() << '\n';
    out << "</DataArray>\n</Points>\n<Verts>\n<DataArray type=\"Int32\" Name=\"connectivity\" format=\"ascii\">\n";
    for (std::size_t i = 0; i < n; ++i) out << i << ' ';
    out << "\n</DataArray>\n<DataArray type=\"Int32\" Name=\"offsets\" format=\"ascii\">\n";
    for (std::size_t i = 1; i <= n; ++i) out << i << ' ';
    out << "\n</DataArray>\n</Verts>\n</Piece>\n</PolyData>\n</VTKFile>\n";
  }
  particles_.emplace_back(time, parts);
}

void FrameSeries::finish() {
  writePvd(surface_pvd_, surface_);
  writePvd(particles_pvd_, particles_);
}

}  // namespace psc::demo
