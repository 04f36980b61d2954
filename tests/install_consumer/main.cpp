#include <psc/psc.h>

#include <cstdio>

int main() {
  const psc::TriMesh m = psc::makeSphere(1.0, 100);
  psc::MeshTopology topo(m.triangles, m.vertices.size());
  std::printf("consumer: %zu vertices, %zu edges\n", topo.vertexCount(), topo.edges().size());
  return topo.edges().empty() ? 1 : 0;
}
