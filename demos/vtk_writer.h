// Frames for ParaView: a time series of VTK XML PolyData files (.vtp, ASCII) with a .pvd
// collection per series, so File > Open on the .pvd gives an animation.
//   <dir>/<run>_surface.pvd    all soft bodies of a step in one .vtp; point data "body",
//                              "region" (-1 for Bullet), "flagged" (vertex in a flagged region;
//                              Bullet: vertex in a contact), "contact", "self_contact" (in a
//                              contact of its body with itself), "missed" (in a strict-truth
//                              contact the pipeline did not find); cell data "body", "flagged"
//   <dir>/<run>_particles.pvd  the sensor particles as points; "body", "region", "flagged"
//   <dir>/<run>_static.vtp     the static boxes (ground, walls)
#pragma once

#include "psc/types.h"

#include <string>
#include <vector>

namespace psc::demo {

struct FrameBody {
  std::vector<Vec3> x;
  const std::vector<Triangle>* triangles = nullptr;
  std::vector<int> region;        ///< per vertex; empty = -1 everywhere
  std::vector<char> flagged;      ///< per vertex
  std::vector<char> contact;      ///< per vertex: in a contact found this step (with another body or itself)
  std::vector<char> self_contact; ///< per vertex: in a contact found this step with its own body
  std::vector<char> missed;       ///< per vertex
};

struct FrameParticle {
  Vec3 x;
  int body = 0;
  int region = 0;
  bool flagged = false;
};

class FrameSeries {
 public:
  /// Creates `dir` if needed. Throws psc::Error(FileError) when it cannot.
  FrameSeries(const std::string& dir, const std::string& run_name);
  void writeStatic(const std::vector<std::pair<Vec3, Vec3>>& boxes);  ///< (center, half extents)
  void writeFrame(std::size_t step, double time, const std::vector<FrameBody>& bodies,
                  const std::vector<FrameParticle>& particles);
  /// Writes the .pvd files listing every frame so far.
  void finish();
  const std::string& surfacePvd() const { return surface_pvd_; }

 private:
  std::string dir_, name_, surface_pvd_, particles_pvd_;
  std::vector<std::pair<double, std::string>> surface_, particles_;
};

}  // namespace psc::demo
