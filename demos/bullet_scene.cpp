#include "bullet_scene.h"

#include "bullet_vf_setup.h"
#include "psc/error.h"

#include <BulletSoftBody/btSoftBodyInternals.h>
#include <BulletSoftBody/btSoftBodyRigidBodyCollisionConfiguration.h>

#include <algorithm>
#include <chrono>
#include <set>

namespace psc::demo {
namespace {

double msSince(std::chrono::steady_clock::time_point t0, std::chrono::steady_clock::time_point t1) {
  return std::chrono::duration<double, std::milli>(t1 - t0).count();
}

btVector3 bt(const Vec3& v) {
  return {static_cast<btScalar>(v.x()), static_cast<btScalar>(v.y()), static_cast<btScalar>(v.z())};
}

}  // namespace

void SceneDynamicsWorld::performDiscreteCollisionDetection() {
  if (before_collision) before_collision();
  btSoftRigidDynamicsWorld::performDiscreteCollisionDetection();
  if (after_collision) after_collision();
}

void TimedSoftBodySolver::predictMotion(btScalar dt) {
  skipped_ = 0;
  predict_ms_ = 0.0;
  face_refit_ms_ = 0.0;
  // btDefaultSoftBodySolver::predictMotion (Bullet 3.24) body by body, so that each body's face
  // refit, and the sensors' refit (after_predict), run while its nodes are in the cache, as the
  // face refit does inside btSoftBody::predictMotion.
  for (int i = 0; i < m_softBodySet.size(); ++i) {
    btSoftBody* psb = m_softBodySet[i];
    if (!psb->isActive()) continue;
    // m_bUpdateRtCst: predictMotion rebuilds the face tree this step; leave that step to Bullet.
    bool split = split_ && !psb->m_bUpdateRtCst && psb->m_fdbvt.m_root != nullptr;
    if (split && psb->m_pose.m_bframe && psb->m_cfg.kMT > 0) {
      ++skipped_;
      split = false;
    }
    btDbvtNode* root = psb->m_fdbvt.m_root;
    if (split) psb->m_fdbvt.m_root = nullptr;  // btDbvt::empty() is m_root == 0: predictMotion skips the face refit
    const auto t0 = std::chrono::steady_clock::now();
    psb->predictMotion(dt);
    const auto t1 = std::chrono::steady_clock::now();
    predict_ms_ += msSince(t0, t1);
    if (split) {
      // The same refit as btSoftBody::predictMotion (Bullet 3.24), with the state it left in m_sst.
      psb->m_fdbvt.m_root = root;
      ATTRIBUTE_ALIGNED16(btDbvtVolume) vol;
      for (int f = 0; f < psb->m_faces.size(); ++f) {
        btSoftBody::Face& face = psb->m_faces[f];
        const btVector3 v = (face.m_n[0]->m_v + face.m_n[1]->m_v + face.m_n[2]->m_v) / 3;
        vol = VolumeOf(face, psb->m_sst.radmrg);
        psb->m_fdbvt.update(face.m_leaf, vol, v * psb->m_sst.velmrg, psb->m_sst.updmrg);
      }
      psb->m_fdbvt.optimizeIncremental(1);
      face_refit_ms_ += msSince(t1, std::chrono::steady_clock::now());
    }
    if (after_predict_) after_predict_(*psb);
  }
}

void TimedSoftBodySolver::solveConstraints(btScalar dt) {
  btDefaultSoftBodySolver::solveConstraints(dt);
  joints_before_self_ = 0;  // 0 in psc_demo: the cluster solve has just deleted its contact joints
  for (int i = 0; i < m_softBodySet.size(); ++i)
    joints_before_self_ += static_cast<std::size_t>(m_softBodySet[i]->m_joints.size());
  self_pass_start_ = std::chrono::steady_clock::now();
}

void TimedSoftBodySolver::updateSoftBodies() {
  std::size_t joints = 0;
  for (int i = 0; i < m_softBodySet.size(); ++i) {
    btSoftBody* psb = m_softBodySet[i];
    if (call_cluster_self_ && psb->m_clusters.size() > 0) {
      btSoftColliders::CollideCL_SS collide;
      collide.ProcessSoftSoft(psb, psb);
    }
    joints += static_cast<std::size_t>(psb->m_joints.size());
  }
  self_pass_ms_ = msSince(self_pass_start_, std::chrono::steady_clock::now());
  self_cluster_contacts_ = joints - std::min(joints, joints_before_self_);
  btDefaultSoftBodySolver::updateSoftBodies();
}

std::size_t jointCount(const std::vector<btSoftBody*>& bodies) {
  std::size_t n = 0;
  for (const btSoftBody* psb : bodies) n += static_cast<std::size_t>(psb->m_joints.size());
  return n;
}

btSoftBody* createSoftBody(btSoftBodyWorldInfo& info, const SoftBodySpec& spec, int collision_flags,
                           int position_iterations, bool fast_vf_setup) {
  const auto& mesh = spec.mesh;
  if (mesh.vertices.empty() || mesh.triangles.empty())
    throw Error(ErrorCode::InvalidMesh, "soft body '" + spec.name + "' has no vertices or no triangles");
  btAlignedObjectArray<btVector3> x;
  btAlignedObjectArray<btScalar> m;
  x.resize(static_cast<int>(mesh.vertices.size()));
  m.resize(static_cast<int>(mesh.vertices.size()), 1);
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i) x[static_cast<int>(i)] = bt(mesh.vertices[i]);
  auto* psb = new btSoftBody(&info, x.size(), &x[0], &m[0]);
  std::set<std::pair<Index, Index>> edges;
  for (const Triangle& t : mesh.triangles)
    for (std::size_t k = 0; k < 3; ++k) edges.insert(std::minmax(t[k], t[(k + 1) % 3]));
  for (const auto& [a, b] : edges) psb->appendLink(static_cast<int>(a), static_cast<int>(b));
  for (const Triangle& t : mesh.triangles)
    psb->appendFace(static_cast<int>(t[0]), static_cast<int>(t[1]), static_cast<int>(t[2]));

  psb->m_materials[0]->m_kLST = static_cast<btScalar>(spec.stiffness);
  if (spec.bending_distance > 0) {
    btSoftBody::Material* bend = psb->appendMaterial();
    bend->m_kLST = static_cast<btScalar>(0.5 * spec.stiffness);
    if (spec.bending_distance == 2)
      appendBendingLinks2(*psb, bend);  // Bullet's own needs n² memory: std::bad_alloc at 50k nodes
    else
      psb->generateBendingConstraints(spec.bending_distance, bend);
  }
  psb->m_cfg.kDF = static_cast<btScalar>(spec.friction);
  psb->m_cfg.kDP = static_cast<btScalar>(spec.damping);
  psb->m_cfg.kPR = static_cast<btScalar>(spec.pressure);
  psb->m_cfg.kVC = static_cast<btScalar>(spec.volume_conservation);
  psb->m_cfg.kMT = 0;
  psb->m_cfg.piterations = position_iterations;
  psb->m_cfg.collisions = collision_flags;
  psb->setTotalMass(static_cast<btScalar>(spec.mass), true);
  for (Index v : spec.pinned) {
    if (v >= mesh.vertices.size()) {
      delete psb;
      throw Error(ErrorCode::InvalidArgument, "soft body '" + spec.name + "': pinned vertex " + std::to_string(v) +
                                                  " is not below its " + std::to_string(mesh.vertices.size()) + " vertices");
    }
    psb->setMass(static_cast<int>(v), 0);  // Bullet keeps nodes of zero mass where they are
  }
  if (spec.volume_conservation > 0) psb->setPose(true, false);  // rest volume only, no frame matching
  psb->getCollisionShape()->setMargin(static_cast<btScalar>(spec.margin));
  psb->setVelocity(bt(spec.velocity));
  if (fast_vf_setup && (collision_flags & btSoftBody::fCollision::SVSmask) == btSoftBody::fCollision::VF_SS) {
    try {
      initializeVFTrees(*psb);
    } catch (const Error& e) {
      delete psb;
      throw Error(e.code(), "soft body '" + spec.name + "': " + e.what());
    }
  }
  return psb;
}

SceneWorld::SceneWorld(const Scene& scene, const WorldOptions& options) : scene_(scene) {
  config_ = std::make_unique<btSoftBodyRigidBodyCollisionConfiguration>();
  dispatcher_ = std::make_unique<btCollisionDispatcher>(config_.get());
  broadphase_ = std::make_unique<btDbvtBroadphase>();
  solver_ = std::make_unique<btSequentialImpulseConstraintSolver>();
  soft_solver_ = std::make_unique<TimedSoftBodySolver>();
  soft_solver_->setSplit(options.split_face_refit);
  soft_solver_->setCallClusterSelf(options.call_cluster_self);
  world_ = std::make_unique<SceneDynamicsWorld>(dispatcher_.get(), broadphase_.get(), solver_.get(), config_.get(),
                                                soft_solver_.get());
  world_->setGravity(bt(scene.gravity));
  world_info_.m_dispatcher = dispatcher_.get();
  world_info_.m_broadphase = broadphase_.get();
  world_info_.m_gravity = bt(scene.gravity);
  world_info_.air_density = 0;
  world_info_.water_density = 0;
  world_info_.m_sparsesdf.Initialize();
  if (options.before_bodies) options.before_bodies(*world_);

  for (const StaticBoxSpec& box : scene.statics) {
    shapes_.push_back(std::make_unique<btBoxShape>(bt(box.half_extents)));
    btTransform tr;
    tr.setIdentity();
    tr.setOrigin(bt(box.center));
    motion_states_.push_back(std::make_unique<btDefaultMotionState>(tr));
    btRigidBody::btRigidBodyConstructionInfo ci(0, motion_states_.back().get(), shapes_.back().get());
    ci.m_friction = 0.8f;
    rigid_.push_back(std::make_unique<btRigidBody>(ci));
    world_->addRigidBody(rigid_.back().get());
  }
  for (const SoftBodySpec& spec : scene.bodies) {
    btSoftBody* psb = createSoftBody(world_info_, spec, options.soft_collision_flags, scene.position_iterations,
                                     options.fast_vf_setup);
    if (options.clusters > 0) psb->generateClusters(options.clusters);
    world_->addSoftBody(psb);
    soft_.push_back(psb);
    face_ranges_.emplace_back(&psb->m_faces[0], &psb->m_faces[0] + psb->m_faces.size());
  }
}

SceneWorld::~SceneWorld() {
  // Attachments (a midphase install handle) go first: they may still refer to the bodies.
  while (!attachments_.empty()) attachments_.pop_back();
  for (btSoftBody* psb : soft_) {
    world_->removeSoftBody(psb);
    delete psb;
  }
  for (auto& body : rigid_) world_->removeRigidBody(body.get());
  world_.reset();
}

void SceneWorld::step() { world_->stepSimulation(static_cast<btScalar>(scene_.dt), 0); }

int SceneWorld::faceOwner(const btSoftBody::Face* face) const {
  for (std::size_t i = 0; i < face_ranges_.size(); ++i)
    if (face >= face_ranges_[i].first && face < face_ranges_[i].second) return static_cast<int>(i);
  return -1;
}

}  // namespace psc::demo
