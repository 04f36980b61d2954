// Deterministic triangle meshes for scenes, tests and examples. All closed shapes are wound
// counter-clockwise seen from outside (outward normals). "Approximately n vertices" means the
// generator picks the tessellation whose vertex count is closest to n.
#pragma once

#include "psc/types.h"

#include <string>
#include <vector>

namespace psc {

struct TriMesh {
  std::vector<Vec3> vertices;
  std::vector<Triangle> triangles;

  TriMesh& translate(const Vec3& offset);
  TriMesh& scale(double factor);
  /// Rotation about `axis` (need not be unit) by `radians`, about the origin.
  TriMesh& rotate(const Vec3& axis, double radians);
};

/// Latitude-longitude sphere with about `vertex_count` vertices (at least 14).
TriMesh makeSphere(double radius, std::size_t vertex_count);
/// Icosphere: 12 vertices at level 0, 42, 162, 642, 2562, 10242, 40962 ... (uniform edges).
TriMesh makeIcosphere(double radius, int subdivisions);
/// Torus around the z axis: major radius R, tube radius r, about `vertex_count` vertices.
TriMesh makeTorus(double major_radius, double minor_radius, std::size_t vertex_count);
/// Closed axis-aligned box centred at the origin with about `vertex_count` vertices on its faces.
TriMesh makeBox(const Vec3& half_extents, std::size_t vertex_count);
/// A U shape (a half torus with straight arms, a closed tube), opening along +y: concave,
/// the thesis's interlocking case. `width` is the distance between the arm axes.
TriMesh makeUShape(double width, double arm_length, double tube_radius, std::size_t vertex_count);
/// Fork: a handle tube splitting into two parallel prongs (the thesis's Fig. 3-7 shape).
TriMesh makeFork(double length, double tube_radius, std::size_t vertex_count);
/// Flat open cloth patch in the xy plane, centred at the origin, nx × ny vertices.
TriMesh makePatch(double width, double height, std::size_t nx, std::size_t ny);

}  // namespace psc
