#include "server/mesh/quality.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace neurosim::mesh {

namespace {
constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = 180.0 / kPi;
}  // namespace

TetQuality tet_quality(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d) {
  const Vec3 p[4] = {a, b, c, d};
  TetQuality q{};
  const Vec3 e1 = b - a, e2 = c - a, e3 = d - a;
  const double det = e1.dot(e2.cross(e3));  // 6 * signed volume
  q.volume_m3 = det / 6.0;

  // Face normals (kTetFaces order); the dihedral angle at the edge shared by faces k and l is
  // pi minus the angle between their normals (orientation cancels out).
  Vec3 n[4];
  bool flat = false;
  for (int k = 0; k < 4; ++k) {
    const auto& f = kTetFaces[k];
    n[k] = (p[f[1]] - p[f[0]]).cross(p[f[2]] - p[f[0]]);
    const double len = n[k].norm();
    if (!(len > 0.0)) flat = true;
    else n[k] /= len;
  }
  if (flat) {
    q.min_dihedral_deg = 0.0;
    q.max_dihedral_deg = 180.0;
  } else {
    q.min_dihedral_deg = 180.0;
    q.max_dihedral_deg = 0.0;
    for (int k = 0; k < 4; ++k)
      for (int l = k + 1; l < 4; ++l) {
        const double cosang = std::clamp(-n[k].dot(n[l]), -1.0, 1.0);
        const double ang = std::acos(cosang) * kDeg;
        q.min_dihedral_deg = std::min(q.min_dihedral_deg, ang);
        q.max_dihedral_deg = std::max(q.max_dihedral_deg, ang);
      }
  }

  // Circumradius from the circumcentre offset relative to a, over the shortest edge.
  double shortest = std::numeric_limits<double>::infinity();
  for (int i = 0; i < 4; ++i)
    for (int j = i + 1; j < 4; ++j) shortest = std::min(shortest, (p[j] - p[i]).norm());
  if (det == 0.0 || !(shortest > 0.0)) {
    q.radius_edge_ratio = std::numeric_limits<double>::infinity();
  } else {
    const Vec3 centre = (e1.squaredNorm() * e2.cross(e3) + e2.squaredNorm() * e3.cross(e1) +
                         e3.squaredNorm() * e1.cross(e2)) /
                        (2.0 * det);
    q.radius_edge_ratio = centre.norm() / shortest;
  }
  return q;
}

QualityReport quality(const std::vector<Vec3>& vertices_m, const std::vector<Tet>& tets,
                      double degenerate_volume_ratio) {
  const std::size_t nv = vertices_m.size();
  for (std::size_t i = 0; i < nv; ++i)
    if (!vertices_m[i].allFinite())
      throw std::invalid_argument("quality: vertex " + std::to_string(i) +
                                  " has a non-finite coordinate");
  double edge_sum = 0.0;
  for (std::size_t t = 0; t < tets.size(); ++t) {
    for (int v : tets[t])
      if (v < 0 || static_cast<std::size_t>(v) >= nv)
        throw std::invalid_argument("quality: tetrahedron " + std::to_string(t) +
                                    " references vertex " + std::to_string(v) + ", outside [0, " +
                                    std::to_string(nv) + ")");
    for (int i = 0; i < 4; ++i)
      for (int j = i + 1; j < 4; ++j)
        edge_sum += (vertices_m[tets[t][j]] - vertices_m[tets[t][i]]).norm();
  }
  QualityReport r;
  r.num_tets = static_cast<int>(tets.size());
  r.num_vertices = static_cast<int>(nv);
  if (tets.empty()) return r;
  const double edge = edge_sum / (6.0 * static_cast<double>(tets.size()));
  const double min_volume = degenerate_volume_ratio * edge * edge * edge;

  r.min_dihedral_deg = 180.0;
  r.max_dihedral_deg = 0.0;
  double ratio_sum = 0.0;
  int counted = 0;
  for (const Tet& t : tets) {
    const TetQuality q =
        tet_quality(vertices_m[t[0]], vertices_m[t[1]], vertices_m[t[2]], vertices_m[t[3]]);
    if (std::abs(q.volume_m3) <= min_volume) {
      ++r.zero_volume;
      continue;
    }
    if (q.volume_m3 < 0.0) ++r.inverted;
    r.min_dihedral_deg = std::min(r.min_dihedral_deg, q.min_dihedral_deg);
    r.max_dihedral_deg = std::max(r.max_dihedral_deg, q.max_dihedral_deg);
    r.max_radius_edge_ratio = std::max(r.max_radius_edge_ratio, q.radius_edge_ratio);
    ratio_sum += q.radius_edge_ratio;
    ++counted;
  }
  if (counted > 0) {
    r.mean_radius_edge_ratio = ratio_sum / counted;
  } else {
    r.min_dihedral_deg = 0.0;
    r.max_dihedral_deg = 0.0;
  }
  return r;
}

QualityReport quality(const TetMesh& mesh, double degenerate_volume_ratio) {
  return quality(mesh.vertices(), mesh.tets(), degenerate_volume_ratio);
}

std::string QualityReport::summary() const {
  std::ostringstream out;
  out.setf(std::ios::fixed);
  out.precision(2);
  out << num_vertices << " vertices, " << num_tets << " tets, dihedral [" << min_dihedral_deg
      << ", " << max_dihedral_deg << "] deg, radius-edge max " << max_radius_edge_ratio << " mean "
      << mean_radius_edge_ratio << ", inverted " << inverted << ", zero-volume " << zero_volume;
  return out.str();
}

}  // namespace neurosim::mesh
