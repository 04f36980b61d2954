// LBG vector quantization of a surface into connected regions (docs/METHOD.md §3, thesis §2.1.3,
// §3.2). One region per sensor particle.
#pragma once

#include "psc/mesh.h"
#include "psc/types.h"

#include <vector>

namespace psc {

enum class SplitRule {
  Thesis,     ///< C·(1 ± ε): cannot split a cluster whose mean is the origin (thesis §5.1.2)
  Principal,  ///< [beyond] C ± ε·σ·e₁ along the cluster's principal direction (default)
};

struct PartitionSettings {
  SplitRule split = SplitRule::Principal;
  double epsilon = 0.005;        ///< Lloyd stop: (D_prev − D)/D_prev ≤ ε; also the split step. (0, 1)
  double normal_weight = 0.5;    ///< w: weight of the normal block in the 6-D feature. ≥ 0
  bool scale_free = true;        ///< [beyond] positions divided by the bounding radius (thesis: raw)
  bool any_count = true;         ///< [beyond] split the worst cluster until the count (thesis: 2^k;
                                 ///< off, a SensorWorld gives each body the largest power of two
                                 ///< within its budget, and a BodyDesc::particles must be one)
  bool connect_regions = true;   ///< [beyond] reassign islands to the neighbour region sharing most edges
  int max_lloyd_iterations = 100;  ///< per split level; hitting it is reported in Partition
};

/// A partition of a mesh's vertices into regions.
struct Partition {
  std::vector<Index> region_of;      ///< region of each vertex (size M)
  std::vector<Index> seed_vertex;    ///< region's vertex nearest its code vector (feature space)
  std::vector<Eigen::Matrix<double, 6, 1>> code_vectors;  ///< final code vectors (feature space)
  double distortion = 0.0;           ///< mean squared feature distance at the end
  int lloyd_iterations = 0;          ///< total over all levels
  bool hit_iteration_cap = false;
  std::size_t islands_reassigned = 0;  ///< vertex islands moved by connectivity repair
  std::size_t empty_reseeded = 0;      ///< empty clusters reseeded
  /// Splits after which the first nearest-code-vector assignment left one of the two children
  /// empty: the split rule did not separate the cluster (SplitRule::Thesis on a cluster whose mean
  /// is the origin, thesis §5.1.2; or a cluster of identical features). The empty child is then
  /// reseeded like any empty cluster, so the count is still reached; this counter is the evidence.
  std::size_t failed_splits = 0;
  /// Regions that are not one connected piece over the one-ring adjacency at the end. 0 whenever
  /// connect_regions is on and count ≥ the number of mesh pieces (components with triangles).
  std::size_t disconnected_regions = 0;
  std::size_t regionCount() const { return seed_vertex.size(); }
};

/// Partitions the mesh into exactly `count` regions (1 ≤ count ≤ vertices in triangles); with
/// `any_count` off, count must be a power of two. Throws psc::Error(InvalidSettings) naming the
/// setting when out of range, psc::Error(InvalidMesh) for a view of the wrong size or a non-finite
/// coordinate. Isolated vertices (in no triangle) join the region of their nearest code vector but
/// are never reachable by hops. Deterministic: same input, same bits.
///
/// Every region is non-empty. With connect_regions on, every region is one connected piece when
/// count ≥ P, P the number of mesh pieces (connected components that have triangles): a piece
/// LBG left without a region takes the label of the smallest region of the piece holding the most
/// regions, which is merged into its neighbour. When count < P connected regions are impossible;
/// then no exception: each region is connected inside every piece it touches and takes whole
/// pieces (the particle reaches only the piece it starts on); disconnected_regions reports it.
/// code_vectors and seed_vertex describe the final (repaired) regions: each code vector is the
/// mean feature of its region.
Partition partitionLBG(const MeshTopology& topology, const PositionView& positions, std::size_t count,
                       const PartitionSettings& settings = {});

/// The 6-D features LBG clusters on (exposed for tests): (x/R, y/R, z/R, w·n) with R the bounding
/// radius about the centroid when scale_free, else raw (x, y, z, w·n).
std::vector<Eigen::Matrix<double, 6, 1>> partitionFeatures(const MeshTopology& topology,
                                                           const PositionView& positions,
                                                           const PartitionSettings& settings);

/// Throws psc::Error(InvalidSettings) when a setting is out of range.
void validate(const PartitionSettings& settings);

}  // namespace psc
