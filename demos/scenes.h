// The benchmark's scenes (docs/BENCHMARK.md, "Scenes"): one definition used by psc_demo, the benchmark
// and the tests. A Scene is plain geometry and material data, independent of Bullet and of the
// midphase; bullet_scene.h turns it into a btSoftRigidDynamicsWorld. Lengths in scene units
// (a "unit" sphere has radius 1), masses in kg, times in seconds.
#pragma once

#include "psc/shapes.h"
#include "psc/types.h"

#include <cstdint>
#include <string>
#include <vector>

namespace psc::demo {

/// What the user asks of a scene. Scenes ignore what does not apply to them.
struct SceneParams {
  std::size_t resolution = 0;     ///< vertices per body (generators pick the nearest tessellation); 0 = the scene's default
  std::size_t bodies = 0;         ///< body count for scenes that take one; 0 = the scene's default
  std::uint64_t seed = 1;         ///< placement jitter and orientations
  std::string mesh_file;          ///< scene 8: OBJ/OFF/PLY/STL; empty = the built-in default
  /// Multiplies every length (and so velocities, gravity, margins) by this factor; the motion in
  /// scene units is unchanged. Bullet's CollideVF_SS skips triangles whose |cross product|² is
  /// ≤ FLT_EPSILON (area ≤ 1.7e-4 units² in single precision), so at scale 1 fine meshes
  /// (~30k+ vertices on a unit sphere) get no soft-soft contacts in either pipeline.
  double scale = 1.0;
};

/// The range of SceneParams::scale the scenes accept (makeScene throws outside it).
inline constexpr double kMinScale = 1e-6, kMaxScale = 1e6;

/// A soft body: a triangle mesh and Bullet material numbers (btSoftBody::Config / Material).
struct SoftBodySpec {
  std::string name;
  TriMesh mesh;
  Vec3 velocity = Vec3::Zero();  ///< initial velocity of every node, units/s
  double mass = 1.0;             ///< total mass, kg, spread over the nodes
  double margin = 0.05;          ///< collision margin, units
  double stiffness = 0.6;        ///< linear stiffness of the edge links, Bullet's kLST in (0, 1]
  double pressure = 0.0;         ///< Bullet's kPR (closed bodies only); 0 = none
  double volume_conservation = 0.0;  ///< Bullet's kVC (closed bodies only); 0 = none
  int bending_distance = 0;      ///< Bullet's generateBendingConstraints distance; 0 = none
  double friction = 0.5;         ///< Bullet's kDF in [0, 1]
  double damping = 0.01;         ///< Bullet's kDP in [0, 1]
  bool closed = false;           ///< every edge shared by exactly two triangles (set by the builder)
  std::vector<Index> pinned;     ///< vertices held in place (Bullet node mass 0), e.g. cloth corners
};

/// A static rigid box (ground, container walls): identical in both pipelines.
struct StaticBoxSpec {
  Vec3 center = Vec3::Zero();
  Vec3 half_extents = Vec3::Ones();
};

struct Scene {
  std::string name;        ///< catalogue name, e.g. "head_on"
  std::string title;       ///< one line for reports
  std::vector<SoftBodySpec> bodies;
  std::vector<StaticBoxSpec> statics;
  Vec3 gravity = Vec3::Zero();  ///< units/s²
  double dt = 1.0 / 60.0;       ///< fixed step, s
  int position_iterations = 4;  ///< Bullet's piterations on every body
  std::size_t default_steps = 120;
  double scale = 1.0;           ///< SceneParams::scale it was built with
  std::string note;             ///< e.g. which mesh file was used
  /// Vertices per body actually used (the generators round); the mean over bodies.
  std::size_t resolution() const;
};

/// One row of the catalogue (--list-scenes).
struct SceneInfo {
  std::string name;
  std::string number;          ///< docs/BENCHMARK.md's numbering: "1", "2a", "2b", ... "8"
  std::string summary;
  bool takes_body_count = false;
  std::size_t default_bodies = 2;
  std::size_t default_steps = 120;
  std::size_t default_resolution = 1000;  ///< vertices per body when SceneParams::resolution is 0
};

/// All scenes, in docs/BENCHMARK.md's order.
const std::vector<SceneInfo>& sceneCatalog();

/// The catalogue row for a name or a number ("head_on", "1", "2b"); nullptr when unknown.
const SceneInfo* findScene(const std::string& name_or_number);

/// Builds a scene. Throws psc::Error (InvalidArgument for an unknown scene or a bad parameter,
/// FileError / InvalidMesh for a mesh file that cannot be used) with a message naming the problem.
Scene makeScene(const std::string& name_or_number, const SceneParams& params);

/// True when every edge of the mesh is shared by exactly two triangles, consistently oriented.
bool isClosed(const TriMesh& mesh);

}  // namespace psc::demo
