#include "server/fusion/carve.hpp"

#include <algorithm>
#include <array>
#include <stdexcept>
#include <string>

namespace neurosim::fusion {

std::vector<char> tets_inside(const mesh::TetMesh& host, const NewBoundary& cut) {
  if (cut.source_tet.size() != cut.triangles.size())
    throw std::invalid_argument("tets_inside: " + std::to_string(cut.triangles.size()) +
                                " triangles but " + std::to_string(cut.source_tet.size()) +
                                " source tetrahedra");
  std::vector<std::array<int, 3>> faces;
  faces.reserve(cut.triangles.size());
  for (const auto& t : cut.triangles) {
    std::array<int, 3> f{t[0], t[1], t[2]};
    std::sort(f.begin(), f.end());
    faces.push_back(f);
  }
  std::sort(faces.begin(), faces.end());
  std::vector<char> inside(host.num_tets(), 0);
  std::vector<int> stack;
  for (int t : cut.source_tet) {
    if (t < 0 || t >= static_cast<int>(host.num_tets()))
      throw std::invalid_argument("tets_inside: source tetrahedron " + std::to_string(t) +
                                  " out of range");
    if (!inside[t]) {
      inside[t] = 1;
      stack.push_back(t);
    }
  }
  while (!stack.empty()) {
    const int t = stack.back();
    stack.pop_back();
    for (int k = 0; k < 4; ++k) {
      const int nb = host.neighbours()[t][k];
      if (nb < 0 || inside[nb]) continue;
      std::array<int, 3> f{};
      for (int a = 0; a < 3; ++a) f[a] = host.tets()[t][mesh::kTetFaces[k][a]];
      std::sort(f.begin(), f.end());
      if (std::binary_search(faces.begin(), faces.end(), f)) continue;
      inside[nb] = 1;
      stack.push_back(nb);
    }
  }
  return inside;
}

}  // namespace neurosim::fusion
