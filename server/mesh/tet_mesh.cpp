#include "server/mesh/tet_mesh.hpp"

#include <algorithm>
#include <cmath>
#include <iostream>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <utility>

namespace neurosim::mesh {

double signed_volume(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d) {
  return (b - a).cross(c - a).dot(d - a) / 6.0;
}

namespace {

// "3, 17, 42 (and 5 more)": the first ids of a list, for messages.
std::string id_list(const std::vector<int>& ids, std::size_t max_shown = 20) {
  std::ostringstream out;
  for (std::size_t i = 0; i < ids.size() && i < max_shown; ++i) out << (i ? ", " : "") << ids[i];
  if (ids.size() > max_shown) out << " (and " << ids.size() - max_shown << " more)";
  return out.str();
}

double mean_edge(const std::vector<Vec3>& v, const std::vector<Tet>& tets) {
  if (tets.empty()) return 0.0;
  double sum = 0.0;
  for (const Tet& t : tets)
    for (int i = 0; i < 4; ++i)
      for (int j = i + 1; j < 4; ++j) sum += (v[t[j]] - v[t[i]]).norm();
  return sum / (6.0 * static_cast<double>(tets.size()));
}

// One face of one tetrahedron, keyed by its sorted vertex ids.
struct FaceRef {
  int b, c;   // second and third smallest vertex (the smallest is the bucket)
  int tet_face;  // 4 * tet + local face
};

}  // namespace

TetMesh TetMesh::build(std::vector<Vec3> vertices_m, std::vector<Tet> tets,
                       const BuildOptions& options) {
  const std::string& src = options.source;
  if (!(options.degenerate_volume_ratio >= 0.0) || !std::isfinite(options.degenerate_volume_ratio))
    throw std::invalid_argument(src + ": degenerate_volume_ratio must be finite and >= 0");
  if (tets.empty()) throw std::invalid_argument(src + ": mesh has no tetrahedra");
  if (vertices_m.size() > static_cast<std::size_t>(std::numeric_limits<int>::max() / 4) ||
      tets.size() > static_cast<std::size_t>(std::numeric_limits<int>::max() / 4))
    throw std::invalid_argument(src + ": mesh too large for 32-bit indices");
  const int nv = static_cast<int>(vertices_m.size());
  const int nt = static_cast<int>(tets.size());

  // Inputs: finite coordinates, indices in range, four distinct vertices.
  for (int i = 0; i < nv; ++i) {
    const Vec3& p = vertices_m[i];
    if (!p.allFinite()) {
      std::ostringstream msg;
      msg << src << ": vertex " << i << " has a non-finite coordinate (" << p.x() << ", " << p.y()
          << ", " << p.z() << ")";
      throw std::invalid_argument(msg.str());
    }
  }
  for (int t = 0; t < nt; ++t) {
    const Tet& tet = tets[t];
    for (int k = 0; k < 4; ++k) {
      if (tet[k] < 0 || tet[k] >= nv) {
        std::ostringstream msg;
        msg << src << ": tetrahedron " << t << " references vertex " << tet[k]
            << ", outside [0, " << nv << ")";
        throw std::invalid_argument(msg.str());
      }
      for (int l = 0; l < k; ++l)
        if (tet[l] == tet[k]) {
          std::ostringstream msg;
          msg << src << ": tetrahedron " << t << " repeats vertex " << tet[k];
          throw std::invalid_argument(msg.str());
        }
    }
  }

  // Degenerate elements are refused; inverted ones are reoriented by swapping two vertices.
  const double edge = mean_edge(vertices_m, tets);
  const double min_volume = options.degenerate_volume_ratio * edge * edge * edge;
  std::vector<int> degenerate, inverted;
  for (int t = 0; t < nt; ++t) {
    Tet& tet = tets[t];
    const double vol =
        signed_volume(vertices_m[tet[0]], vertices_m[tet[1]], vertices_m[tet[2]], vertices_m[tet[3]]);
    // Not finite (coordinates so large that the products overflow, e.g. 1e200 m) counts as
    // degenerate: no element can be computed from it. NaN fails every comparison, hence !(>).
    if (!(std::abs(vol) > min_volume) || !std::isfinite(vol)) {
      degenerate.push_back(t);
    } else if (vol < 0.0) {
      std::swap(tet[2], tet[3]);
      inverted.push_back(t);
    }
  }
  if (!degenerate.empty()) {
    std::ostringstream msg;
    msg << src << ": " << degenerate.size()
        << " degenerate tetrahedra (|volume| <= " << options.degenerate_volume_ratio
        << " * mean edge^3 = " << min_volume << " m^3, or not finite): " << id_list(degenerate);
    throw std::invalid_argument(msg.str());
  }
  if (!inverted.empty())
    std::cerr << "warning: " << src << ": reoriented " << inverted.size()
              << " inverted tetrahedra: " << id_list(inverted) << "\n";

  TetMesh m;
  m.source_ = src;
  m.inverted_fixed_ = static_cast<int>(inverted.size());

  // Drop unused vertices, keeping the source index of each kept one.
  std::vector<int> new_id(nv, -1);
  if (options.drop_unused_vertices) {
    for (const Tet& tet : tets)
      for (int v : tet) new_id[v] = 0;
    int next = 0;
    for (int i = 0; i < nv; ++i)
      if (new_id[i] == 0) new_id[i] = next++;
    m.vertices_.reserve(next);
    m.source_vertex_ids_.reserve(next);
    for (int i = 0; i < nv; ++i)
      if (new_id[i] >= 0) {
        m.vertices_.push_back(vertices_m[i]);
        m.source_vertex_ids_.push_back(i);
      }
    for (Tet& tet : tets)
      for (int& v : tet) v = new_id[v];
  } else {
    m.vertices_ = std::move(vertices_m);
    m.source_vertex_ids_.resize(nv);
    for (int i = 0; i < nv; ++i) m.source_vertex_ids_[i] = i;
  }
  m.tets_ = std::move(tets);
  m.tet_labels_.assign(nt, 0);
  const int n = static_cast<int>(m.vertices_.size());

  // Face matching: bucket every face by its smallest vertex (counting sort), then sort each
  // small bucket by the other two; equal keys are shared faces. O(n) plus tiny sorts.
  std::vector<int> bucket_start(n + 1, 0);
  std::vector<std::array<int, 3>> keys(static_cast<std::size_t>(4) * nt);
  for (int t = 0; t < nt; ++t)
    for (int k = 0; k < 4; ++k) {
      const auto& f = kTetFaces[k];
      int a = m.tets_[t][f[0]], b = m.tets_[t][f[1]], c = m.tets_[t][f[2]];
      if (a > b) std::swap(a, b);
      if (b > c) std::swap(b, c);
      if (a > b) std::swap(a, b);
      keys[4 * t + k] = {a, b, c};
      ++bucket_start[a + 1];
    }
  for (int i = 0; i < n; ++i) bucket_start[i + 1] += bucket_start[i];
  std::vector<FaceRef> faces(keys.size());
  {
    std::vector<int> fill(bucket_start.begin(), bucket_start.end() - 1);
    for (int tf = 0; tf < 4 * nt; ++tf) {
      const auto& key = keys[tf];
      faces[fill[key[0]]++] = FaceRef{key[1], key[2], tf};
    }
  }
  m.neighbours_.assign(nt, {-1, -1, -1, -1});
  for (int a = 0; a < n; ++a) {
    auto first = faces.begin() + bucket_start[a];
    auto last = faces.begin() + bucket_start[a + 1];
    std::sort(first, last, [](const FaceRef& x, const FaceRef& y) {
      return x.b != y.b ? x.b < y.b : (x.c != y.c ? x.c < y.c : x.tet_face < y.tet_face);
    });
    for (auto it = first; it != last;) {
      auto end = it + 1;
      while (end != last && end->b == it->b && end->c == it->c) ++end;
      const int count = static_cast<int>(end - it);
      if (count > 2) {
        std::ostringstream msg;
        msg << src << ": face (" << m.source_vertex_ids_[a] << ", " << m.source_vertex_ids_[it->b]
            << ", " << m.source_vertex_ids_[it->c] << ") is shared by " << count
            << " tetrahedra (non-manifold):";
        for (auto f = it; f != end; ++f) msg << " " << f->tet_face / 4;
        throw std::invalid_argument(msg.str());
      }
      if (count == 2) {
        const int t0 = it->tet_face / 4, k0 = it->tet_face % 4;
        const int t1 = (it + 1)->tet_face / 4, k1 = (it + 1)->tet_face % 4;
        if (t0 == t1 || m.neighbours_[t0][0] == t1 || m.neighbours_[t0][1] == t1 ||
            m.neighbours_[t0][2] == t1 || m.neighbours_[t0][3] == t1) {
          std::ostringstream msg;
          msg << src << ": tetrahedra " << t0 << " and " << t1
              << " share more than one face (duplicate elements)";
          throw std::invalid_argument(msg.str());
        }
        m.neighbours_[t0][k0] = t1;
        m.neighbours_[t1][k1] = t0;
      } else {
        // Boundary face, outward because the tetrahedron is positive (kTetFaces order).
        const int t = it->tet_face / 4, k = it->tet_face % 4;
        const auto& f = kTetFaces[k];
        m.surface_.push_back({m.tets_[t][f[0]], m.tets_[t][f[1]], m.tets_[t][f[2]]});
        m.surface_tet_.push_back(t);
      }
      it = end;
    }
  }

  // Surface vertices, sorted.
  {
    std::vector<char> on(n, 0);
    for (const Tri& tri : m.surface_)
      for (int v : tri) on[v] = 1;
    for (int i = 0; i < n; ++i)
      if (on[i]) m.surface_vertices_.push_back(i);
  }

  // Vertex -> tetrahedra (CSR).
  m.vertex_tet_offsets_.assign(n + 1, 0);
  for (const Tet& tet : m.tets_)
    for (int v : tet) ++m.vertex_tet_offsets_[v + 1];
  for (int i = 0; i < n; ++i) m.vertex_tet_offsets_[i + 1] += m.vertex_tet_offsets_[i];
  m.vertex_tet_list_.resize(m.vertex_tet_offsets_[n]);
  {
    std::vector<int> fill(m.vertex_tet_offsets_.begin(), m.vertex_tet_offsets_.end() - 1);
    for (int t = 0; t < nt; ++t)
      for (int v : m.tets_[t]) m.vertex_tet_list_[fill[v]++] = t;
  }
  return m;
}

void TetMesh::set_tet_labels(std::vector<int> labels) {
  if (labels.size() != tets_.size()) {
    std::ostringstream msg;
    msg << source_ << ": " << labels.size() << " tetrahedron labels for " << tets_.size()
        << " tetrahedra";
    throw std::invalid_argument(msg.str());
  }
  tet_labels_ = std::move(labels);
}

double TetMesh::tet_volume(int t) const {
  if (t < 0 || static_cast<std::size_t>(t) >= tets_.size())
    throw std::out_of_range(source_ + ": tetrahedron " + std::to_string(t) + " out of range");
  const Tet& tet = tets_[t];
  return signed_volume(vertices_[tet[0]], vertices_[tet[1]], vertices_[tet[2]], vertices_[tet[3]]);
}

void TetMesh::bounds(Vec3& lo, Vec3& hi) const {
  if (vertices_.empty()) {
    lo.setZero();
    hi.setZero();
    return;
  }
  lo = hi = vertices_.front();
  for (const Vec3& p : vertices_) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
}

double TetMesh::mean_edge_length() const { return mean_edge(vertices_, tets_); }

}  // namespace neurosim::mesh
