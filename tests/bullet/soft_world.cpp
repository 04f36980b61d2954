#include "soft_world.h"

#include <BulletCollision/CollisionShapes/btBoxShape.h>
#include <BulletSoftBody/btSoftBodyHelpers.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>

namespace psc_test {
namespace {
constexpr double kPi = 3.14159265358979323846;
}  // namespace

SoftWorld::SoftWorld(double gravity, const DispatcherFactory& make_dispatcher, bool psc_solver)
    : own_dispatcher_(make_dispatcher ? make_dispatcher(&config) : std::make_unique<btCollisionDispatcher>(&config)),
      dispatcher(*own_dispatcher_),
      psc_solver_(psc_solver) {
  world.setGravity(btVector3(0, btScalar(gravity), 0));
  world.getWorldInfo().m_gravity.setValue(0, btScalar(gravity), 0);
  world.getWorldInfo().m_sparsesdf.Initialize();
  world.setInternalTickCallback(&SoftWorld::tick, this);
}

SoftWorld::~SoftWorld() {
  for (btSoftBody* body : soft_) {
    world.removeSoftBody(body);
    delete body;
  }
  for (auto& body : rigid_) world.removeRigidBody(body.get());
}

void SoftWorld::tick(btDynamicsWorld* world, btScalar) {
  auto* self = static_cast<SoftWorld*>(world->getWorldUserInfo());
  if (self->after_dispatch_) self->after_dispatch_();
}

void SoftWorld::run(int n, const std::function<void()>& after_dispatch, double dt) {
  after_dispatch_ = after_dispatch;
  for (int i = 0; i < n; ++i) step(dt);
  after_dispatch_ = nullptr;
}

btSoftBody* SoftWorld::addSoft(const psc::TriMesh& mesh, const SoftParams& params, const btVector3& velocity) {
  std::vector<btScalar> xyz;
  for (const psc::Vec3& v : mesh.vertices)
    for (int k = 0; k < 3; ++k) xyz.push_back(btScalar(v[k]));
  std::vector<int> triangles;
  for (const psc::Triangle& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) triangles.push_back(int(t[std::size_t(k)]));
  btSoftBody* body = btSoftBodyHelpers::CreateFromTriMesh(world.getWorldInfo(), xyz.data(), triangles.data(),
                                                          int(mesh.triangles.size()), false);
  body->getCollisionShape()->setMargin(btScalar(params.margin));
  btSoftBody::Material* material = body->m_materials[0];
  material->m_kLST = btScalar(params.stiffness);
  body->generateBendingConstraints(2, material);
  body->m_cfg.piterations = params.iterations;
  body->m_cfg.kDF = btScalar(params.friction);
  body->m_cfg.kDP = btScalar(params.damping);
  body->setTotalMass(btScalar(params.mass), false);
  if (params.shape_matching > 0) {
    body->m_cfg.kMT = btScalar(params.shape_matching);
    body->setPose(false, true);
  }
  body->m_cfg.collisions = btSoftBody::fCollision::SDF_RS | (params.vf_ss ? btSoftBody::fCollision::VF_SS : 0);
  body->setVelocity(velocity);
  world.addSoftBody(body);
  soft_.push_back(body);
  return body;
}

btRigidBody* SoftWorld::addBox(const btVector3& half_extents, double mass, const btVector3& position) {
  shapes_.push_back(std::make_unique<btBoxShape>(half_extents));
  btCollisionShape* shape = shapes_.back().get();
  btVector3 inertia(0, 0, 0);
  if (mass > 0) shape->calculateLocalInertia(btScalar(mass), inertia);
  btTransform transform;
  transform.setIdentity();
  transform.setOrigin(position);
  motion_states_.push_back(std::make_unique<btDefaultMotionState>(transform));
  btRigidBody::btRigidBodyConstructionInfo info(btScalar(mass), motion_states_.back().get(), shape, inertia);
  info.m_friction = 0.8f;
  rigid_.push_back(std::make_unique<btRigidBody>(info));
  world.addRigidBody(rigid_.back().get());
  return rigid_.back().get();
}

void SoftWorld::destroySoft(btSoftBody* body) {
  world.removeSoftBody(body);
  soft_.erase(std::find(soft_.begin(), soft_.end(), body));
  delete body;
}

btVector3 centroid(const btSoftBody& body) {
  btVector3 sum(0, 0, 0);
  for (int i = 0; i < body.m_nodes.size(); ++i) sum += body.m_nodes[i].m_x;
  return sum / btScalar(body.m_nodes.size());
}

std::size_t positionHash(const btAlignedObjectArray<btSoftBody*>& bodies) {
  std::size_t hash = 1469598103934665603ull;
  for (int b = 0; b < bodies.size(); ++b)
    for (int i = 0; i < bodies[b]->m_nodes.size(); ++i)
      for (int k = 0; k < 3; ++k) {
        btScalar value = bodies[b]->m_nodes[i].m_x[k];
        unsigned char bytes[sizeof(btScalar)];
        std::memcpy(bytes, &value, sizeof value);
        for (unsigned char byte : bytes) hash = (hash ^ byte) * 1099511628211ull;
      }
  return hash;
}

const char* sceneName(Scene scene) {
  switch (scene) {
    case Scene::HeadOn: return "head-on";
    case Scene::ThreeInARow: return "three-in-a-row";
    case Scene::Concave: return "linked-tori";
    case Scene::Pile: return "mixed-pile";
  }
  return "?";
}

int sceneSteps(Scene scene) { return scene == Scene::Pile ? 150 : 45; }
double sceneGravity(Scene scene) { return scene == Scene::Pile ? -10.0 : 0.0; }

void buildScene(Scene scene, SoftWorld& w, bool vf_ss) {
  SoftParams p;
  p.vf_ss = vf_ss;
  switch (scene) {
    case Scene::HeadOn: {  // thesis case 1: two equal spheres, 3 m/s each way (5 cm a step)
      w.addSoft(psc::makeSphere(0.5, 300).translate({-0.6, 0, 0}), p, {3, 0, 0});
      w.addSoft(psc::makeSphere(0.5, 300).translate({0.6, 0.05, 0}), p, {-3, 0, 0});
      break;
    }
    case Scene::ThreeInARow: {  // thesis cases 2 and 3: D, D/2, D in a row, the outer ones closing in
      w.addSoft(psc::makeSphere(0.5, 250).translate({-0.9, 0, 0}), p, {3, 0, 0});
      w.addSoft(psc::makeSphere(0.25, 150).translate({0, 0.03, 0}), p, {0, 0, 0});
      w.addSoft(psc::makeSphere(0.5, 250).translate({0.9, 0, 0.02}), p, {-3, 0, 0});
      break;
    }
    case Scene::Concave: {  // thesis case 4: two linked rings pulled apart, tube against tube in the hole
      w.addSoft(psc::makeTorus(0.6, 0.15, 400), p, {-2, 0, 0});
      w.addSoft(psc::makeTorus(0.6, 0.15, 400).rotate({1, 0, 0}, kPi / 2).translate({0.6, 0, 0}), p, {2, 0, 0});
      break;
    }
    case Scene::Pile: {  // thesis case 6: mixed bodies dropped in a column onto a static floor
      w.addBox({3, 0.5, 3}, 0, {0, -0.5, 0});
      w.addSoft(psc::makeSphere(0.3, 160).translate({0, 0.35, 0}), p);
      w.addSoft(psc::makeTorus(0.3, 0.1, 200).rotate({1, 0, 0}, kPi / 2).translate({0.05, 1.0, 0}), p);
      w.addSoft(psc::makeSphere(0.25, 120).translate({-0.05, 1.5, 0.05}), p);
      w.addSoft(psc::makeUShape(0.4, 0.3, 0.08, 200).translate({0, 2.0, 0}), p);
      w.addSoft(psc::makeSphere(0.3, 160).translate({0.1, 2.6, -0.05}), p);
      w.addSoft(psc::makeTorus(0.25, 0.08, 160).translate({0, 3.1, 0}), p);
      SoftParams cloth = p;
      cloth.shape_matching = 0.0;
      w.addSoft(psc::makePatch(0.9, 0.9, 10, 10).rotate({1, 0, 0}, kPi / 2).translate({0, 3.5, 0}), cloth);
      break;
    }
  }
}

}  // namespace psc_test
