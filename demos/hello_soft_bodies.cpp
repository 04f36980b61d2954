// Hello, soft bodies: an ordinary Bullet 3.24 soft-body program plus one line,
// psc::bullet::install(world), after which soft bodies collide through psc's particle sensors
// instead of Bullet's refitted trees. Two soft balls fall onto each other and a static floor.
// Exits with 1 if the upper ball ends below the top of the lower one (CTest runs this program).
#include <psc/bullet/bullet.h>
#include <psc/shapes.h>

#include <BulletCollision/CollisionShapes/btStaticPlaneShape.h>
#include <BulletSoftBody/btSoftBodyHelpers.h>
#include <BulletSoftBody/btSoftBodyRigidBodyCollisionConfiguration.h>
#include <BulletSoftBody/btSoftRigidDynamicsWorld.h>
#include <btBulletDynamicsCommon.h>

#include <cstdio>
#include <vector>

// A soft ball from psc's mesh generator; any triangle mesh would do.
static btSoftBody* makeBall(btSoftBodyWorldInfo& info, btScalar radius, const btVector3& centre) {
  const psc::TriMesh mesh = psc::makeSphere(radius, 400);
  std::vector<btScalar> xyz;
  for (const psc::Vec3& v : mesh.vertices)
    xyz.insert(xyz.end(), {btScalar(v.x()) + centre.x(), btScalar(v.y()) + centre.y(), btScalar(v.z()) + centre.z()});
  std::vector<int> triangles;
  for (const psc::Triangle& t : mesh.triangles) triangles.insert(triangles.end(), {int(t[0]), int(t[1]), int(t[2])});
  btSoftBody* ball = btSoftBodyHelpers::CreateFromTriMesh(info, xyz.data(), triangles.data(), int(mesh.triangles.size()));
  ball->generateBendingConstraints(2);
  ball->m_cfg.piterations = 8;
  ball->m_cfg.kMT = 0.3f;         // shape matching keeps the ball round
  ball->setPose(false, true);
  ball->setTotalMass(1.0f);
  ball->getCollisionShape()->setMargin(0.02f);
  // Soft-soft collision is off by default in Bullet; VF_SS switches it on, and with the plugin
  // installed the same flag makes the body one of the sensors' (Settings::opt_in).
  ball->m_cfg.collisions |= btSoftBody::fCollision::VF_SS;
  return ball;
}

int main() {
  btSoftBodyRigidBodyCollisionConfiguration config;
  btCollisionDispatcher dispatcher(&config);
  btDbvtBroadphase broadphase;
  btSequentialImpulseConstraintSolver solver;
  btSoftRigidDynamicsWorld world(&dispatcher, &broadphase, &solver, &config);
  world.setGravity(btVector3(0, -10, 0));
  world.getWorldInfo().m_gravity.setValue(0, -10, 0);
  world.getWorldInfo().m_sparsesdf.Initialize();

  btStaticPlaneShape floor_shape(btVector3(0, 1, 0), 0);
  btRigidBody floor(0, nullptr, &floor_shape);
  world.addRigidBody(&floor);
  btSoftBody* lower = makeBall(world.getWorldInfo(), 0.5f, btVector3(0, 0.55f, 0));
  btSoftBody* upper = makeBall(world.getWorldInfo(), 0.4f, btVector3(0.05f, 1.7f, 0));
  world.addSoftBody(lower);
  world.addSoftBody(upper);

  // The one call. The plugin uninstalls itself when it goes out of scope (before the world).
  psc::bullet::Plugin plugin = psc::bullet::install(world);

  for (int step = 1; step <= 90; ++step) {
    world.stepSimulation(1.0f / 60.0f, 0);
    if (step % 30 == 0) {
      const psc::bullet::Stats& s = plugin.stats();
      std::printf("step %2d: %zu particles, %zu flagged region pairs, %zu exact tests, %zu contacts, "
                  "sensors %.2f ms, exact %.2f ms\n",
                  step, s.particles, s.flagged_pairs, s.exact_tests, s.contacts, s.ms_sensor_step, s.ms_exact);
    }
  }
  btScalar lower_top = -1e9f, upper_centre = 0;
  for (int i = 0; i < lower->m_nodes.size(); ++i) lower_top = btMax(lower_top, lower->m_nodes[i].m_x.y());
  for (int i = 0; i < upper->m_nodes.size(); ++i) upper_centre += upper->m_nodes[i].m_x.y() / btScalar(upper->m_nodes.size());
  std::printf("upper ball centre %.3f m, top of the lower ball %.3f m\n", double(upper_centre), double(lower_top));

  plugin.uninstall();
  world.removeSoftBody(upper);
  world.removeSoftBody(lower);
  world.removeRigidBody(&floor);
  delete upper;
  delete lower;
  return upper_centre > lower_top ? 0 : 1;
}
