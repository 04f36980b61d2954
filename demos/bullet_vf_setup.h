// Bullet 3.24 setup steps that are quadratic in the vertex count, redone in near-linear time with
// identical results (tests/demos compares them with Bullet's own, element by element).
//
// Bullet 3.24 builds a VF_SS body's trees at its first predictMotion (the m_bUpdateRtCst branch:
// updateConstants(), then initializeFaceTree(), which also calls rebuildNodeTree()). Both trees
// come from a bottom-up merge of adjacent leaves whose adjacency is found with an all-pairs loop
// over the faces and an all-pairs loop per level: O(F²). Measured on one core: 3 s for a
// 4,000-vertex body, 48 s for two 16,000-vertex bodies, i.e. hours for the 50k-100k sweeps.
// It also never terminates when the adjacency graph is disconnected (a mesh in several pieces):
// the merge loop waits for one root forever.
//
// initializeVFTrees() does the same work in O(F log F) and produces the same trees: same leaves,
// same pairing order, same node volumes (tests/demos checks the trees against Bullet's own, node
// by node). Per-step behaviour is therefore Bullet's; only this one-time setup is faster. A body in
// several pieces gets psc::Error instead of a hang.
#pragma once

#include <BulletSoftBody/btSoftBody.h>

namespace psc::demo {

/// Does what btSoftBody::predictMotion does when m_bUpdateRtCst is set and VF_SS is on, and clears
/// the flag so predictMotion does not do it again. Call after masses, pose and margin are set.
/// Throws psc::Error(InvalidMesh) when the faces (or links) do not form one connected piece.
void initializeVFTrees(btSoftBody& body);

/// Bullet's generateBendingConstraints(2, material): a link, flagged m_bbending, between every
/// two nodes at graph distance exactly 2, appended in Bullet's order (by lower index, then higher).
/// Bullet's own allocates an n×n matrix (10 GB at 50,000 nodes, std::bad_alloc); this one is
/// O(n·degree²). Returns the number of links added.
int appendBendingLinks2(btSoftBody& body, btSoftBody::Material* material);

/// True when the two trees have the same shape, the same leaf data and the same volumes.
bool sameTree(const btDbvtNode* a, const btDbvtNode* b, const btSoftBody& owner_a, const btSoftBody& owner_b,
              bool faces);

}  // namespace psc::demo
