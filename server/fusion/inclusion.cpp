#include "server/fusion/inclusion.hpp"

#include "server/fusion/cgal_aabb.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <set>
#include <stdexcept>
#include <string>

namespace neurosim::fusion {
namespace {

using namespace cgal_aabb;

CGAL::Bbox_3 box_of(const P3& a, const P3& b, const P3& c) {
  return a.bbox() + b.bbox() + c.bbox();
}

// B's triangles as kernel objects, validated once per call.
struct Prepared {
  std::vector<T3> tris;
  std::vector<CGAL::Bbox_3> boxes;
  CGAL::Bbox_3 box;
  bool empty{true};
};

Prepared prepare(const TriangleSurface& s, bool validate) {
  if (validate) validate_closed(s);
  Prepared out;
  out.tris.reserve(s.triangles.size());
  out.boxes.reserve(s.triangles.size());
  for (std::size_t i = 0; i < s.triangles.size(); ++i) {
    const Tri& t = s.triangles[i];
    const P3 a = to_point(s.vertices_m[t[0]]);
    const P3 b = to_point(s.vertices_m[t[1]]);
    const P3 c = to_point(s.vertices_m[t[2]]);
    // CGAL's triangle predicates require non-degenerate triangles.
    if (validate && CGAL::collinear(a, b, c)) {
      throw std::invalid_argument("surface '" + s.name + "': triangle " + std::to_string(i) +
                                  " (vertices " + std::to_string(t[0]) + "," +
                                  std::to_string(t[1]) + "," + std::to_string(t[2]) +
                                  ") is degenerate (collinear)");
    }
    out.tris.emplace_back(a, b, c);
    out.boxes.push_back(box_of(a, b, c));
    out.box = out.empty ? out.boxes.back() : out.box + out.boxes.back();
    out.empty = false;
  }
  return out;
}

// --- Inside/outside by segment parity, exact orientation predicates only -------------------

enum class Crossing { kNone, kProper, kDegenerate, kOnSurface };

// Does segment p->q cross triangle abc through its interior? q is outside B's box, so it is
// never on a triangle; p on a triangle is reported (caller's contract says it is not).
Crossing classify(const P3& p, const P3& q, const T3& t) {
  const P3& a = t[0];
  const P3& b = t[1];
  const P3& c = t[2];
  const CGAL::Orientation sp = CGAL::orientation(a, b, c, p);
  const CGAL::Orientation sq = CGAL::orientation(a, b, c, q);
  if (sp != CGAL::COPLANAR && sp == sq) return Crossing::kNone;
  if (sp == CGAL::COPLANAR && sq == CGAL::COPLANAR) {
    // Segment in the triangle's plane: p on the (closed) triangle, or retry with another q.
    // coplanar_orientation(x, y, p) is a consistent 2D orientation inside the plane.
    const CGAL::Orientation e0 = CGAL::coplanar_orientation(a, b, p);
    const CGAL::Orientation e1 = CGAL::coplanar_orientation(b, c, p);
    const CGAL::Orientation e2 = CGAL::coplanar_orientation(c, a, p);
    const bool neg = e0 == CGAL::NEGATIVE || e1 == CGAL::NEGATIVE || e2 == CGAL::NEGATIVE;
    const bool pos = e0 == CGAL::POSITIVE || e1 == CGAL::POSITIVE || e2 == CGAL::POSITIVE;
    return (neg && pos) ? Crossing::kDegenerate : Crossing::kOnSurface;
  }
  // The line pq meets the plane at one point X (p if sp is 0, q if sq is 0, else inside pq).
  const CGAL::Orientation o0 = CGAL::orientation(p, q, a, b);
  const CGAL::Orientation o1 = CGAL::orientation(p, q, b, c);
  const CGAL::Orientation o2 = CGAL::orientation(p, q, c, a);
  const bool neg = o0 == CGAL::NEGATIVE || o1 == CGAL::NEGATIVE || o2 == CGAL::NEGATIVE;
  const bool pos = o0 == CGAL::POSITIVE || o1 == CGAL::POSITIVE || o2 == CGAL::POSITIVE;
  if (neg && pos) return Crossing::kNone;                  // X outside the triangle
  if (sp == CGAL::COPLANAR) return Crossing::kOnSurface;   // X = p lies on the triangle
  if (sq == CGAL::COPLANAR) return Crossing::kDegenerate;  // cannot happen: q outside B's box
  if (o0 != CGAL::COPLANAR && o1 != CGAL::COPLANAR && o2 != CGAL::COPLANAR) {
    return Crossing::kProper;
  }
  return Crossing::kDegenerate;  // through an edge or a vertex of B: retry
}

// End point of the parity segment: beyond the nearest face of B's box, with an offset in the
// two other coordinates that changes with the attempt (a new, generic direction on retry).
P3 far_point(const P3& p, const CGAL::Bbox_3& box, int attempt) {
  const double lo[3] = {box.xmin(), box.ymin(), box.zmin()};
  const double hi[3] = {box.xmax(), box.ymax(), box.zmax()};
  const double pc[3] = {p.x(), p.y(), p.z()};
  int axis = 0;
  bool up = true;
  double best = hi[0] - pc[0];
  for (int d = 0; d < 3; ++d) {
    if (hi[d] - pc[d] < best) {
      best = hi[d] - pc[d];
      axis = d;
      up = true;
    }
    if (pc[d] - lo[d] < best) {
      best = pc[d] - lo[d];
      axis = d;
      up = false;
    }
  }
  // Rotate the axis on later attempts so a bad plane is left behind.
  axis = (axis + attempt / 4) % 3;
  const double extent = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2], 1e-9});
  double q[3] = {pc[0], pc[1], pc[2]};
  q[axis] = up ? hi[axis] + 0.25 * extent : lo[axis] - 0.25 * extent;
  const double len = std::abs(q[axis] - pc[axis]);
  // Irrational-looking slopes, different per attempt.
  const double s1 = std::fmod(0.6180339887 * (attempt + 1), 1.0) - 0.5;
  const double s2 = std::fmod(0.4142135623 * (attempt + 1) + 0.2718281828, 1.0) - 0.5;
  q[(axis + 1) % 3] += 0.37 * s1 * len;
  q[(axis + 2) % 3] += 0.29 * s2 * len;
  return P3(q[0], q[1], q[2]);
}

bool inside_box(const P3& p, const CGAL::Bbox_3& b) {
  return p.x() >= b.xmin() && p.x() <= b.xmax() && p.y() >= b.ymin() && p.y() <= b.ymax() &&
         p.z() >= b.zmin() && p.z() <= b.zmax();
}

constexpr int kMaxAttempts = 24;

[[noreturn]] void throw_on_surface(const P3& p) {
  throw std::invalid_argument("point (" + std::to_string(p.x()) + ", " + std::to_string(p.y()) +
                              ", " + std::to_string(p.z()) +
                              ") m lies on the closed surface: inside/outside undefined");
}

// Parity over all triangles (reference).
bool outside_brute(const P3& p, const Prepared& b) {
  if (b.empty || !inside_box(p, b.box)) return true;
  for (int attempt = 0; attempt < kMaxAttempts; ++attempt) {
    const P3 q = far_point(p, b.box, attempt);
    int crossings = 0;
    bool retry = false;
    for (const T3& t : b.tris) {
      const Crossing c = classify(p, q, t);
      if (c == Crossing::kProper) ++crossings;
      if (c == Crossing::kOnSurface) throw_on_surface(p);
      if (c == Crossing::kDegenerate) {
        retry = true;
        break;
      }
    }
    if (!retry) return crossings % 2 == 0;
  }
  throw std::runtime_error("inside/outside test: no generic ray found after " +
                           std::to_string(kMaxAttempts) + " attempts");
}

// --- Traversal traits over the hierarchy (box tests only at nodes: conservative, exact) ----

struct SegmentParity {
  const Prepared* b;
  P3 p, q;
  CGAL::Bbox_3 box;
  int crossings{0};
  bool retry{false};
  bool on_surface{false};
  bool go_further() const { return !retry && !on_surface; }
  void intersection(const CGAL::Bbox_3&, const Primitive& prim) {
    const std::size_t i = static_cast<std::size_t>(prim.id() - b->tris.begin());
    if (!CGAL::do_overlap(box, b->boxes[i])) return;
    const Crossing c = classify(p, q, b->tris[i]);
    if (c == Crossing::kProper) ++crossings;
    if (c == Crossing::kDegenerate) retry = true;
    if (c == Crossing::kOnSurface) on_surface = true;
  }
  template <class Node>
  bool do_intersect(const CGAL::Bbox_3&, const Node& node) const {
    return CGAL::do_overlap(box, node.bbox());
  }
};

struct TriangleHit {
  const Prepared* b;
  T3 face;
  CGAL::Bbox_3 box;
  std::size_t tests{0};
  bool hit{false};
  bool go_further() const { return !hit; }
  void intersection(const CGAL::Bbox_3&, const Primitive& prim) {
    const std::size_t i = static_cast<std::size_t>(prim.id() - b->tris.begin());
    if (!CGAL::do_overlap(box, b->boxes[i])) return;
    ++tests;
    if (CGAL::do_intersect(face, b->tris[i])) hit = true;
  }
  template <class Node>
  bool do_intersect(const CGAL::Bbox_3&, const Node& node) const {
    return CGAL::do_overlap(box, node.bbox());
  }
};

struct BoxHit {
  const Prepared* b;
  bool hit{false};
  bool go_further() const { return !hit; }
  void intersection(const CGAL::Bbox_3& box, const Primitive& prim) {
    const std::size_t i = static_cast<std::size_t>(prim.id() - b->tris.begin());
    if (CGAL::do_overlap(box, b->boxes[i])) hit = true;
  }
  template <class Node>
  bool do_intersect(const CGAL::Bbox_3& box, const Node& node) const {
    return CGAL::do_overlap(box, node.bbox());
  }
};

// Collects the triangles of B whose boxes overlap a tetrahedron's box: the candidates for all
// four of its faces, found in one descent.
struct BoxCollect {
  const Prepared* b;
  std::vector<int>* out;
  bool go_further() const { return true; }
  void intersection(const CGAL::Bbox_3& box, const Primitive& prim) {
    const std::size_t i = static_cast<std::size_t>(prim.id() - b->tris.begin());
    if (CGAL::do_overlap(box, b->boxes[i])) out->push_back(static_cast<int>(i));
  }
  template <class Node>
  bool do_intersect(const CGAL::Bbox_3& box, const Node& node) const {
    return CGAL::do_overlap(box, node.bbox());
  }
};

bool outside_tree(const P3& p, const Prepared& b, const Tree& tree) {
  if (b.empty || !inside_box(p, b.box)) return true;
  for (int attempt = 0; attempt < kMaxAttempts; ++attempt) {
    SegmentParity sp{&b, p, far_point(p, b.box, attempt), {}};
    sp.box = p.bbox() + sp.q.bbox();
    tree.traversal(sp.box, sp);
    if (sp.on_surface) throw_on_surface(p);
    if (!sp.retry) return sp.crossings % 2 == 0;
  }
  throw std::runtime_error("inside/outside test: no generic ray found after " +
                           std::to_string(kMaxAttempts) + " attempts");
}

std::size_t inside_triangles(const mesh::TetMesh& a) {
  return 4 * a.num_tets() - a.surface().size();
}

CGAL::Bbox_3 host_box(const std::vector<P3>& pts) {
  CGAL::Bbox_3 box;
  bool first = true;
  for (const P3& p : pts) {
    box = first ? p.bbox() : box + p.bbox();
    first = false;
  }
  return box;
}

std::vector<P3> host_points(const mesh::TetMesh& a) {
  std::vector<P3> pts;
  pts.reserve(a.num_vertices());
  for (const Vec3& v : a.vertices()) pts.push_back(to_point(v));
  return pts;
}

mesh::Tri face_of(const mesh::Tet& tet, int k) {
  const auto& f = mesh::kTetFaces[k];
  return {tet[f[0]], tet[f[1]], tet[f[2]]};
}

std::array<int, 3> sorted(const mesh::Tri& t) {
  std::array<int, 3> s{t[0], t[1], t[2]};
  std::sort(s.begin(), s.end());
  return s;
}

}  // namespace

std::vector<int> NewBoundary::vertices() const {
  std::vector<int> v;
  v.reserve(triangles.size() * 3);
  for (const auto& t : triangles) v.insert(v.end(), t.begin(), t.end());
  std::sort(v.begin(), v.end());
  v.erase(std::unique(v.begin(), v.end()), v.end());
  return v;
}

bool outside_closed_surface(const Vec3& p_m, const TriangleSurface& surface) {
  if (!p_m.allFinite()) throw std::invalid_argument("outside_closed_surface: non-finite point");
  return outside_brute(to_point(p_m), prepare(surface, true));
}

std::vector<char> outside_closed_surface(const std::vector<Vec3>& points_m,
                                         const TriangleSurface& surface) {
  std::vector<char> out(points_m.size(), 1);
  if (points_m.empty()) return out;
  const Prepared b = prepare(surface, true);
  Tree tree(b.tris.cbegin(), b.tris.cend());
  tree.do_not_accelerate_distance_queries();
  for (std::size_t i = 0; i < points_m.size(); ++i) {
    if (!points_m[i].allFinite())
      throw std::invalid_argument("outside_closed_surface: non-finite point " + std::to_string(i));
    out[i] = outside_tree(to_point(points_m[i]), b, tree) ? 1 : 0;
  }
  return out;
}

NewBoundary find_new_boundary_bruteforce(const mesh::TetMesh& host,
                                         const TriangleSurface& embedded) {
  const Prepared b = prepare(embedded, true);
  const std::vector<P3> pts = host_points(host);
  NewBoundary out;
  InclusionStats& st = out.stats;
  st.host_tets = host.num_tets();
  st.inside_triangles = inside_triangles(host);
  // Step 2: whole-mesh boxes.
  if (pts.empty() || !CGAL::do_overlap(host_box(pts), b.box)) {
    st.tets_culled = host.num_tets();
    return out;
  }
  std::set<std::array<int, 3>> hit_faces;
  std::set<std::array<int, 3>> emitted;
  const auto& tets = host.tets();
  for (std::size_t t = 0; t < tets.size(); ++t) {
    ++st.tets_checked;
    // Step 3: every face against every surface triangle.
    int count = 0;
    std::array<bool, 4> hit{};
    for (int k = 0; k < 4; ++k) {
      const mesh::Tri f = face_of(tets[t], k);
      const T3 face(pts[f[0]], pts[f[1]], pts[f[2]]);
      ++st.face_queries;
      for (const T3& tri : b.tris) {
        ++st.triangle_tests;
        if (CGAL::do_intersect(face, tri)) hit[k] = true;
      }
      if (hit[k]) {
        ++count;
        hit_faces.insert(sorted(f));
      }
    }
    if (count > 0) ++st.intersected_tets;
    if (count == 0 || count == 4) continue;
    ++st.partial_tets;
    // Step 4: the non-intersected faces outside B join S'.
    for (int k = 0; k < 4; ++k) {
      if (hit[k]) continue;
      const mesh::Tri f = face_of(tets[t], k);
      if (emitted.count(sorted(f)) != 0) continue;
      ++st.point_queries;
      if (!outside_brute(pts[f[0]], b)) continue;
      emitted.insert(sorted(f));
      out.triangles.push_back(f);
      out.source_tet.push_back(static_cast<int>(t));
    }
  }
  st.intersected_faces = hit_faces.size();
  return out;
}

NewBoundary find_new_boundary(const mesh::TetMesh& host, const TriangleSurface& embedded,
                              const InclusionOptions& options) {
  const Prepared b = prepare(embedded, options.validate_embedded);
  NewBoundary out;
  InclusionStats& st = out.stats;
  st.host_tets = host.num_tets();
  st.inside_triangles = inside_triangles(host);
  const auto& verts = host.vertices();
  if (verts.empty() || b.empty) {
    st.tets_culled = host.num_tets();
    return out;
  }
  Tree tree(b.tris.cbegin(), b.tris.cend());
  tree.do_not_accelerate_distance_queries();
  st.bvh_bytes =
      b.tris.size() * (sizeof(T3) + sizeof(CGAL::Bbox_3) + sizeof(Primitive)) +
      (b.tris.size() > 0 ? b.tris.size() - 1 : 0) * (sizeof(CGAL::Bbox_3) + 2 * sizeof(void*));

  const auto& tets = host.tets();
  const auto& nbr = host.neighbours();
  // Per (tet, local face): bit 0 known, bit 1 intersects B, bit 2 already in S'.
  std::vector<std::uint8_t> face_state(4 * tets.size(), 0);
  // Per vertex of A: 0 unknown, 1 outside B, 2 inside B.
  std::vector<std::uint8_t> vertex_side(verts.size(), 0);
  std::vector<int> candidates;
  candidates.reserve(64);
  auto partner = [&](std::size_t t, int k) -> std::size_t {
    const int n = nbr[t][k];
    if (n < 0) return static_cast<std::size_t>(-1);
    for (int j = 0; j < 4; ++j) {
      if (nbr[n][j] == static_cast<int>(t)) return 4 * static_cast<std::size_t>(n) + j;
    }
    throw std::logic_error("host mesh adjacency is not symmetric at tetrahedron " +
                           std::to_string(t));
  };
  auto mark = [&](std::size_t t, int k, std::uint8_t bits) {
    face_state[4 * t + k] |= bits;
    const std::size_t p = partner(t, k);
    if (p != static_cast<std::size_t>(-1)) face_state[p] |= bits;
  };

  for (std::size_t t = 0; t < tets.size(); ++t) {
    const mesh::Tet& tet = tets[t];
    CGAL::Bbox_3 tb = to_point(verts[tet[0]]).bbox();
    for (int i = 1; i < 4; ++i) tb += to_point(verts[tet[i]]).bbox();
    // Step 2 per tetrahedron: its box against B's box, then against B's triangle boxes.
    if (!CGAL::do_overlap(tb, b.box)) {
      ++st.tets_culled;
      continue;
    }
    if (options.candidates_per_tetrahedron) {
      candidates.clear();
      BoxCollect bc{&b, &candidates};
      tree.traversal(tb, bc);
    } else {
      BoxHit bh{&b};
      tree.traversal(tb, bh);
      if (!bh.hit)
        candidates.clear();
      else
        candidates.assign(1, -1);  // non-empty marker: query the tree per face below
    }
    if (candidates.empty()) {
      ++st.tets_culled;
      continue;
    }
    ++st.tets_checked;
    // Step 3 with a cache: a face shared by two tetrahedra is tested once.
    int count = 0;
    for (int k = 0; k < 4; ++k) {
      std::uint8_t s = face_state[4 * t + k];
      if ((s & 1) == 0) {
        const mesh::Tri f = face_of(tet, k);
        const P3 a = to_point(verts[f[0]]), bb = to_point(verts[f[1]]), c = to_point(verts[f[2]]);
        TriangleHit th{&b, T3(a, bb, c), box_of(a, bb, c)};
        ++st.face_queries;
        if (options.candidates_per_tetrahedron) {
          // The face lies in the tetrahedron's box: B's candidates for it are among the tet's.
          for (int i : candidates) {
            if (!CGAL::do_overlap(th.box, b.boxes[i])) continue;
            ++th.tests;
            if (CGAL::do_intersect(th.face, b.tris[i])) {
              th.hit = true;
              break;
            }
          }
        } else {
          tree.traversal(th.box, th);
        }
        st.triangle_tests += th.tests;
        if (th.hit) ++st.intersected_faces;
        mark(t, k, th.hit ? 3 : 1);
        s = face_state[4 * t + k];
      }
      if (s & 2) ++count;
    }
    if (count > 0) ++st.intersected_tets;
    if (count == 0 || count == 4) continue;
    ++st.partial_tets;
    // Step 4: a face that touches no triangle of B is wholly inside or outside; one vertex
    // decides, and a vertex's answer is cached (it is shared by many faces).
    for (int k = 0; k < 4; ++k) {
      const std::uint8_t s = face_state[4 * t + k];
      if ((s & 2) || (s & 4)) continue;
      const mesh::Tri f = face_of(tet, k);
      int v = f[0];
      for (int i = 0; i < 3; ++i) {
        if (vertex_side[f[i]] != 0) {
          v = f[i];
          break;
        }
      }
      if (vertex_side[v] == 0) {
        ++st.point_queries;
        vertex_side[v] = outside_tree(to_point(verts[v]), b, tree) ? 1 : 2;
      }
      if (vertex_side[v] != 1) continue;
      mark(t, k, 4);
      out.triangles.push_back(f);
      out.source_tet.push_back(static_cast<int>(t));
    }
  }
  return out;
}

}  // namespace neurosim::fusion
