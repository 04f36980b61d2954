#include "bullet_vf_setup.h"

#include "psc/error.h"

#include <BulletSoftBody/btSoftBodyInternals.h>

#include <algorithm>
#include <map>
#include <string>
#include <vector>

namespace psc::demo {
namespace {

btDbvtNode* newNode() { return new (btAlignedAlloc(sizeof(btDbvtNode), 16)) btDbvtNode(); }

// Frees a (partial) tree built with newNode(), leaves included.
void freeTree(btDbvtNode* n) {
  if (!n) return;
  if (!n->isleaf()) {
    freeTree(n->childs[0]);
    freeTree(n->childs[1]);
  }
  n->~btDbvtNode();
  btAlignedFree(n);
}

/// Bullet 3.24's buildTreeBottomUp (btSoftBody.cpp), with the per-level adjacency computed from
/// the children's lists instead of an all-pairs loop. Level-0 lists are used in the order given
/// (the pairing takes the first unmarked neighbour); Bullet's higher levels come out sorted and
/// unique, and so do ours.
btDbvtNode* buildBottomUp(std::vector<btDbvtNode*> leaves, std::vector<std::vector<int>> adj, const char* what) {
  if (leaves.empty()) return nullptr;
  while (leaves.size() > 1) {
    const std::size_t n = leaves.size();
    std::vector<char> marked(n, 0);
    std::vector<btDbvtNode*> next;
    std::vector<std::pair<int, int>> children;
    for (std::size_t i = 0; i < n; ++i) {
      if (marked[i]) continue;
      bool merged = false;
      for (int j : adj[i]) {
        if (marked[static_cast<std::size_t>(j)]) continue;
        btDbvtNode* node = newNode();
        node->parent = nullptr;
        node->childs[0] = leaves[i];
        node->childs[1] = leaves[static_cast<std::size_t>(j)];
        leaves[i]->parent = node;
        leaves[static_cast<std::size_t>(j)]->parent = node;
        next.push_back(node);
        children.emplace_back(static_cast<int>(i), j);
        merged = true;
        marked[static_cast<std::size_t>(j)] = 1;
        break;
      }
      if (!merged) {
        next.push_back(leaves[i]);
        children.emplace_back(static_cast<int>(i), -1);
      }
      marked[i] = 1;
    }
    if (next.size() == n) {
      for (btDbvtNode* root : next) freeTree(root);  // nothing of the partial forest is kept
      throw Error(ErrorCode::InvalidMesh,
                  std::string("the body's ") + what +
                      " are in several unconnected pieces: Bullet 3.24's VF_SS tree builder would never finish "
                      "(btSoftBody::initializeFaceTree loops forever); keep one connected piece per soft body");
    }
    std::vector<int> parent(n);
    for (std::size_t k = 0; k < children.size(); ++k) {
      parent[static_cast<std::size_t>(children[k].first)] = static_cast<int>(k);
      if (children[k].second >= 0) parent[static_cast<std::size_t>(children[k].second)] = static_cast<int>(k);
    }
    std::vector<std::vector<int>> next_adj(next.size());
    for (std::size_t k = 0; k < children.size(); ++k) {
      for (int c : {children[k].first, children[k].second}) {
        if (c < 0) continue;
        for (int m : adj[static_cast<std::size_t>(c)]) {
          const int p = parent[static_cast<std::size_t>(m)];
          if (p != static_cast<int>(k)) next_adj[k].push_back(p);
        }
      }
      std::sort(next_adj[k].begin(), next_adj[k].end());
      next_adj[k].erase(std::unique(next_adj[k].begin(), next_adj[k].end()), next_adj[k].end());
    }
    leaves = std::move(next);
    adj = std::move(next_adj);
  }
  return leaves[0];
}

btDbvntNode* copyToDbvnt(const btDbvtNode* n) {
  if (!n) return nullptr;
  auto* root = new btDbvntNode(n);
  if (n->isinternal()) {
    root->childs[0] = copyToDbvnt(n->childs[0]);
    root->childs[1] = copyToDbvnt(n->childs[1]);
  }
  return root;
}

void rebuildNodeTree(btSoftBody& b) {
  b.m_ndbvt.clear();
  const int n = b.m_nodes.size();
  std::vector<btDbvtNode*> leaves(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) {
    btSoftBody::Node& node = b.m_nodes[i];
    ATTRIBUTE_ALIGNED16(btDbvtVolume) vol = btDbvtVolume::FromCR(node.m_x, 0);
    btDbvtNode* leaf = newNode();
    leaf->parent = nullptr;
    leaf->data = &node;
    leaf->childs[1] = nullptr;
    leaf->volume = vol;
    leaves[static_cast<std::size_t>(i)] = leaf;
    node.m_leaf = leaf;
  }
  // Link order, duplicates kept: exactly Bullet's level-0 lists.
  std::vector<std::vector<int>> adj(static_cast<std::size_t>(n));
  for (int i = 0; i < b.m_links.size(); ++i) {
    const btSoftBody::Link& l = b.m_links[i];
    const int a = static_cast<int>(l.m_n[0] - &b.m_nodes[0]), c = static_cast<int>(l.m_n[1] - &b.m_nodes[0]);
    adj[static_cast<std::size_t>(a)].push_back(c);
    adj[static_cast<std::size_t>(c)].push_back(a);
  }
  b.m_ndbvt.m_root = buildBottomUp(std::move(leaves), std::move(adj), "nodes (through their links)");
}

}  // namespace

void initializeVFTrees(btSoftBody& b) {
  b.m_bUpdateRtCst = false;
  b.updateConstants();
  b.m_fdbvt.clear();
  const int nf = b.m_faces.size();
  std::vector<btDbvtNode*> leaves(static_cast<std::size_t>(nf));
  for (int i = 0; i < nf; ++i) {
    btSoftBody::Face& f = b.m_faces[i];
    ATTRIBUTE_ALIGNED16(btDbvtVolume) vol = VolumeOf(f, 0);
    btDbvtNode* leaf = newNode();
    leaf->parent = nullptr;
    leaf->data = &f;
    leaf->childs[1] = nullptr;
    leaf->volume = vol;
    leaves[static_cast<std::size_t>(i)] = leaf;
    f.m_leaf = leaf;
  }
  // Bullet's test: faces sharing at least two nodes, i.e. an edge; its lists come out ascending
  // (with repeats that do not change the pairing).
  std::map<std::pair<const void*, const void*>, std::vector<int>> by_edge;
  for (int i = 0; i < nf; ++i)
    for (int k = 0; k < 3; ++k) {
      const void* p = b.m_faces[i].m_n[k];
      const void* q = b.m_faces[i].m_n[(k + 1) % 3];
      by_edge[std::minmax(p, q)].push_back(i);
    }
  std::vector<std::vector<int>> adj(static_cast<std::size_t>(nf));
  for (const auto& [edge, faces] : by_edge)
    for (int f : faces)
      for (int g : faces)
        if (f != g) adj[static_cast<std::size_t>(f)].push_back(g);
  for (auto& list : adj) {
    std::sort(list.begin(), list.end());
    list.erase(std::unique(list.begin(), list.end()), list.end());
  }
  try {
    b.m_fdbvt.m_root = buildBottomUp(std::move(leaves), std::move(adj), "triangles (through shared edges)");
  } catch (...) {
    // buildBottomUp freed the partial trees, leaves included: leave the body without a face tree.
    b.m_fdbvt.m_root = nullptr;
    for (int i = 0; i < nf; ++i) b.m_faces[i].m_leaf = nullptr;
    throw;
  }
  delete b.m_fdbvnt;
  b.m_fdbvnt = copyToDbvnt(b.m_fdbvt.m_root);
  b.updateFaceTree(false, false);
  rebuildNodeTree(b);
}

int appendBendingLinks2(btSoftBody& b, btSoftBody::Material* material) {
  const int n = b.m_nodes.size();
  std::vector<std::vector<int>> near(static_cast<std::size_t>(n));
  for (int i = 0; i < b.m_links.size(); ++i) {
    const int x = static_cast<int>(b.m_links[i].m_n[0] - &b.m_nodes[0]);
    const int y = static_cast<int>(b.m_links[i].m_n[1] - &b.m_nodes[0]);
    near[static_cast<std::size_t>(x)].push_back(y);
    near[static_cast<std::size_t>(y)].push_back(x);
  }
  for (auto& list : near) {
    std::sort(list.begin(), list.end());
    list.erase(std::unique(list.begin(), list.end()), list.end());
  }
  int added = 0;
  std::vector<int> ring;
  for (int j = 0; j < n; ++j) {
    const auto& first = near[static_cast<std::size_t>(j)];
    ring.clear();
    for (int k : first)
      for (int i : near[static_cast<std::size_t>(k)])
        if (i > j && !std::binary_search(first.begin(), first.end(), i)) ring.push_back(i);
    std::sort(ring.begin(), ring.end());
    ring.erase(std::unique(ring.begin(), ring.end()), ring.end());
    for (int i : ring) {
      b.appendLink(i, j, material);
      // Bullet writes 1 into this signed 1-bit field, which stores -1: store the same bits.
      b.m_links[b.m_links.size() - 1].m_bbending = -1;
      ++added;
    }
  }
  return added;
}

bool sameTree(const btDbvtNode* a, const btDbvtNode* b, const btSoftBody& oa, const btSoftBody& ob, bool faces) {
  if (!a || !b) return a == b;
  if (a->isleaf() != b->isleaf()) return false;
  const auto eq = [](const btVector3& x, const btVector3& y) { return x.x() == y.x() && x.y() == y.y() && x.z() == y.z(); };
  if (!eq(a->volume.Mins(), b->volume.Mins()) || !eq(a->volume.Maxs(), b->volume.Maxs())) return false;
  if (a->isleaf()) {
    if (faces)
      return static_cast<const btSoftBody::Face*>(a->data) - &oa.m_faces[0] ==
             static_cast<const btSoftBody::Face*>(b->data) - &ob.m_faces[0];
    return static_cast<const btSoftBody::Node*>(a->data) - &oa.m_nodes[0] ==
           static_cast<const btSoftBody::Node*>(b->data) - &ob.m_nodes[0];
  }
  return sameTree(a->childs[0], b->childs[0], oa, ob, faces) && sameTree(a->childs[1], b->childs[1], oa, ob, faces);
}

}  // namespace psc::demo
