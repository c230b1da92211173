#include "server/fusion/carve.hpp"

#include <algorithm>
#include <array>

namespace neurosim::fusion {

std::vector<char> tets_inside(const mesh::TetMesh& host, const std::vector<mesh::Tri>& cut) {
  std::vector<std::array<int, 3>> faces;
  faces.reserve(cut.size());
  for (const auto& t : cut) {
    std::array<int, 3> f{t[0], t[1], t[2]};
    std::sort(f.begin(), f.end());
    faces.push_back(f);
  }
  std::sort(faces.begin(), faces.end());
  std::vector<char> outside(host.num_tets(), 0);
  std::vector<int> stack;
  for (int t : host.surface_tet()) {
    if (!outside[t]) {
      outside[t] = 1;
      stack.push_back(t);
    }
  }
  while (!stack.empty()) {
    const int t = stack.back();
    stack.pop_back();
    for (int k = 0; k < 4; ++k) {
      const int nb = host.neighbours()[t][k];
      if (nb < 0 || outside[nb]) continue;
      std::array<int, 3> f{};
      for (int a = 0; a < 3; ++a) f[a] = host.tets()[t][mesh::kTetFaces[k][a]];
      std::sort(f.begin(), f.end());
      if (std::binary_search(faces.begin(), faces.end(), f)) continue;
      outside[nb] = 1;
      stack.push_back(nb);
    }
  }
  for (auto& o : outside) o = !o;
  return outside;  // now: inside
}

}  // namespace neurosim::fusion
