// Resampling of the MRI through the deformed meshes (see resample.hpp).
#include "viewer_client/resample.hpp"

#include <Eigen/Geometry>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <unordered_map>
#include <utility>

namespace neurosim::viewer {

namespace {

using Eigen::Vector3d;
using Box = Eigen::AlignedBox3d;

// Barycentric tolerance: a point this far (in weight) outside a face still counts as inside, so
// points on shared faces always find a tetrahedron despite rounding.
constexpr double kBaryEps = 1e-9;
// Deformed |det| below this fraction of the rest |det|: degenerate, never searched.
constexpr double kDegenerateRatio = 1e-6;
// A sample within this many voxels of a voxel centre reads that voxel exactly.
constexpr double kSnapVoxels = 1e-9;
// A tetrahedron whose bounding box covers more grid cells goes to the per-mesh "big" list.
constexpr long long kMaxCellsPerTet = 4096;
// Upper bound on the cells of one mesh's grid (the cell grows to stay under it).
constexpr long long kMaxGridCells = 1LL << 21;

std::string where(const MeshGeometry& m, std::size_t index) {
  return "mesh " + std::to_string(index) + " '" + m.id + "'";
}

// Containment data of one deformed tetrahedron: rows of the inverse edge matrix and vertex 0.
// Barycentric weights (w1, w2, w3) = inv * (p - o); w0 = 1 - w1 - w2 - w3.
struct TetSearch {
  double inv[9];
  double o[3];
};

// Rest vertex 0 and rest edges (columns), for X = x0 + E * (w1, w2, w3).
struct TetRest {
  double x0[3];
  double e[9];  // row-major 3x3, columns are the edges x1-x0, x2-x0, x3-x0
};

enum TetKind : std::uint8_t { kPositive = 0, kInverted = 1, kDegenerate = 2 };

// Barycentric weights (w1, w2, w3) of p; true when p is inside (within kBaryEps). The one place
// this arithmetic is written, so the point search and the slice/volume rasterization agree bit
// for bit (the project builds without -march, so no FMA contraction differs between sites).
inline bool barycentric(const TetSearch& s, const double p[3], double w[3]) {
  const double dx = p[0] - s.o[0], dy = p[1] - s.o[1], dz = p[2] - s.o[2];
  w[0] = s.inv[0] * dx + s.inv[1] * dy + s.inv[2] * dz;
  w[1] = s.inv[3] * dx + s.inv[4] * dy + s.inv[5] * dz;
  w[2] = s.inv[6] * dx + s.inv[7] * dy + s.inv[8] * dz;
  // Written so that NaN fails.
  return w[0] >= -kBaryEps && w[1] >= -kBaryEps && w[2] >= -kBaryEps &&
         w[0] + w[1] + w[2] <= 1.0 + kBaryEps;
}

inline bool box_contains(const Box& b, const double p[3]) {
  return p[0] >= b.min()[0] && p[0] <= b.max()[0] && p[1] >= b.min()[1] && p[1] <= b.max()[1] &&
         p[2] >= b.min()[2] && p[2] <= b.max()[2];
}

inline void rest_point(const TetRest& r, const double w[3], double x[3]) {
  for (int a = 0; a < 3; ++a)
    x[a] = r.x0[a] + r.e[3 * a] * w[0] + r.e[3 * a + 1] * w[1] + r.e[3 * a + 2] * w[2];
}

// A tetrahedron of some mesh.
struct TetRef {
  int mesh;
  int tet;
};

// A regular grid of sample points in a plane: point (a, b) has coordinate `position` along
// `axis`, origin_u + a * step_u along the first other axis and origin_v + b * step_v along the
// second. Slices and the volume's z planes are both this.
struct PlaneGrid {
  int axis = 2;
  double position = 0.0;
  double origin_u = 0.0, step_u = 1.0, origin_v = 0.0, step_v = 1.0;
  int width = 0, height = 0;
  int u_axis() const { return axis == 0 ? 1 : 0; }
  int v_axis() const { return axis == 2 ? 1 : 2; }
};

// Index range [i0, i1] of grid points origin + i * step (0 <= i < n) that may lie in [lo, hi]
// (one point of margin: callers test the exact point).
void index_range(double lo, double hi, double origin, double step, int n, int& i0, int& i1) {
  i0 = static_cast<int>(std::clamp(std::ceil((lo - origin) / step) - 1.0, 0.0, 1.0 * n));
  i1 = static_cast<int>(std::clamp(std::floor((hi - origin) / step) + 1.0, -1.0, n - 1.0));
}

// Where a tetrahedron sits in its mesh's grid.
struct CellRange {
  int lo[3]{0, 0, 0};
  int hi[3]{-1, -1, -1};
  bool big = false;     // in the big list instead of the cells
  bool listed = false;  // in the grid at all (false: degenerate)
};

struct Grid {
  Vector3d origin{Vector3d::Zero()};
  double cell_m = 1.0;
  double inv_cell = 1.0;
  int n[3]{1, 1, 1};
  Box domain;
  std::vector<std::vector<int>> cells;  // each sorted ascending
  std::vector<int> big;                 // sorted ascending

  std::size_t index(int i, int j, int k) const {
    return static_cast<std::size_t>(i) +
           static_cast<std::size_t>(n[0]) *
               (static_cast<std::size_t>(j) + static_cast<std::size_t>(n[1]) * k);
  }
};

void insert_sorted(std::vector<int>& v, int t) {
  v.insert(std::lower_bound(v.begin(), v.end(), t), t);
}
void erase_sorted(std::vector<int>& v, int t) {
  auto it = std::lower_bound(v.begin(), v.end(), t);
  if (it != v.end() && *it == t) v.erase(it);
}

struct MeshState {
  MeshGeometry geo;
  std::size_t tet_offset = 0;          // global tetrahedron index of tet 0
  std::vector<double> rest_sign;       // +1 / -1: orientation of the rest tetrahedron
  std::vector<double> rest_abs_det;    // |det| of the rest edge matrix (m^3)
  std::vector<TetRest> rest;           // constant
  std::vector<Vector3d> u;             // current displacement (m)
  std::vector<Vector3d> u_reported;    // displacement when the vertex last counted as moved
  std::vector<Vector3d> x;             // deformed positions (m)
  std::vector<TetSearch> search;       // deformed containment data
  std::vector<std::uint8_t> kind;      // TetKind
  std::vector<std::uint8_t> identity;  // all four vertices have u == 0 exactly
  std::vector<Box> box;                // deformed bounding box (padded)
  std::vector<CellRange> range;
  std::vector<int> vt_offsets, vt_list;  // vertex -> tetrahedra (CSR)
  Grid grid;
  Box bounds;  // deformed bounds of every listed tetrahedron
};

// Per-output incremental state.
struct OutputState {
  bool is_slice = true;
  std::uint64_t token = 0;      // also in the output object (sampler_token)
  std::uint64_t last_used = 0;  // Impl::use_counter at the last update
  const float* data = nullptr;
  std::size_t size = 0;
  // Slice geometry at the last update.
  int axis = 0;
  double position_m = 0.0;
  int width = 0, height = 0;
  Vector3d origin{Vector3d::Zero()};
  Eigen::Vector2d spacing{Eigen::Vector2d::Zero()};
  // Moved since the last update.
  Box dirty;
  std::vector<std::uint8_t> moved;  // per global tetrahedron
  std::size_t moved_count = 0;
};

bool finite3(const Vector3d& v) { return v.allFinite(); }

}  // namespace

// ------------------------------------------------------------------------------------------------
// ImageGrid and free functions

namespace {

// ImageGrid::validate without the per-voxel finiteness scan (cheap: for make_image_slice).
void validate_geometry(const ImageGrid& g) {
  const auto& dims = g.dims;
  const auto& spacing_m = g.spacing_m;
  const auto& origin_m = g.origin_m;
  const auto& values = g.values;
  long double count = 1;
  for (int a = 0; a < 3; ++a) {
    if (dims[a] <= 0) {
      throw std::invalid_argument("ImageGrid: dims[" + std::to_string(a) +
                                  "] = " + std::to_string(dims[a]) + " is not positive");
    }
    count *= dims[a];
    if (!std::isfinite(spacing_m[a]) || !(spacing_m[a] > 0.0)) {
      throw std::invalid_argument("ImageGrid: spacing_m[" + std::to_string(a) +
                                  "] is not finite and positive");
    }
    if (!std::isfinite(origin_m[a])) {
      throw std::invalid_argument("ImageGrid: origin_m[" + std::to_string(a) + "] is not finite");
    }
  }
  if (count > static_cast<long double>(std::numeric_limits<std::ptrdiff_t>::max()) ||
      static_cast<std::size_t>(count) != values.size()) {
    throw std::invalid_argument("ImageGrid: " + std::to_string(values.size()) +
                                " values for dims " + std::to_string(dims[0]) + " x " +
                                std::to_string(dims[1]) + " x " + std::to_string(dims[2]));
  }
}

}  // namespace

void ImageGrid::validate() const {
  validate_geometry(*this);
  for (std::size_t n = 0; n < values.size(); ++n) {
    if (!std::isfinite(values[n])) {
      const std::size_t i = n % static_cast<std::size_t>(dims[0]);
      const std::size_t j = (n / static_cast<std::size_t>(dims[0])) % dims[1];
      const std::size_t k = n / (static_cast<std::size_t>(dims[0]) * dims[1]);
      throw std::invalid_argument("ImageGrid: value at voxel (" + std::to_string(i) + ", " +
                                  std::to_string(j) + ", " + std::to_string(k) + ") is not finite");
    }
  }
}

namespace {

// sample_trilinear on a validated image (inlined into the rasterizer).
inline float trilinear(const ImageGrid& image, const double p_m[3], float outside) {
  double f[3];
  bool on_voxel = true;
  for (int a = 0; a < 3; ++a) {
    f[a] = (p_m[a] - image.origin_m[a]) / image.spacing_m[a];
    const double last = image.dims[a] - 1;
    // Also false for NaN.
    if (!(f[a] >= -kSnapVoxels && f[a] <= last + kSnapVoxels)) return outside;
    // f >= -kSnapVoxels here, so truncation of f + 0.5 rounds (no libm call).
    const double r = static_cast<double>(static_cast<long long>(f[a] + 0.5));
    if (std::abs(f[a] - r) <= kSnapVoxels) {
      f[a] = r;
    } else {
      on_voxel = false;
    }
  }
  // Exactly on a voxel: its value, bit for bit.
  if (on_voxel) {
    return image.values[image.index(static_cast<int>(f[0]), static_cast<int>(f[1]),
                                    static_cast<int>(f[2]))];
  }
  int i0[3];
  double t[3];
  for (int a = 0; a < 3; ++a) {
    // f >= 0 after snapping: truncation is floor.
    i0[a] = std::clamp(static_cast<int>(f[a]), 0, std::max(image.dims[a] - 2, 0));
    t[a] = image.dims[a] > 1 ? f[a] - i0[a] : 0.0;
  }
  const int sx = image.dims[0] > 1 ? 1 : 0;
  const std::size_t sy = image.dims[1] > 1 ? static_cast<std::size_t>(image.dims[0]) : 0;
  const std::size_t sz =
      image.dims[2] > 1 ? static_cast<std::size_t>(image.dims[0]) * image.dims[1] : 0;
  const float* v = image.values.data() + image.index(i0[0], i0[1], i0[2]);
  const double c00 = v[0] + t[0] * (static_cast<double>(v[sx]) - v[0]);
  const double c10 = v[sy] + t[0] * (static_cast<double>(v[sy + sx]) - v[sy]);
  const double c01 = v[sz] + t[0] * (static_cast<double>(v[sz + sx]) - v[sz]);
  const double c11 = v[sz + sy] + t[0] * (static_cast<double>(v[sz + sy + sx]) - v[sz + sy]);
  const double c0 = c00 + t[1] * (c10 - c00);
  const double c1 = c01 + t[1] * (c11 - c01);
  return static_cast<float>(c0 + t[2] * (c1 - c0));
}

}  // namespace

float sample_trilinear(const ImageGrid& image, const Eigen::Vector3d& p_m, float outside) {
  if (image.dims[0] <= 0 || image.dims[1] <= 0 || image.dims[2] <= 0 ||
      image.values.size() !=
          static_cast<std::size_t>(image.dims[0]) * image.dims[1] * image.dims[2]) {
    throw std::invalid_argument("sample_trilinear: " + std::to_string(image.values.size()) +
                                " values for dims " + std::to_string(image.dims[0]) + " x " +
                                std::to_string(image.dims[1]) + " x " +
                                std::to_string(image.dims[2]));
  }
  return trilinear(image, p_m.data(), outside);
}

Slice make_image_slice(const ImageGrid& image, int axis, double position_m) {
  validate_geometry(image);
  if (axis < 0 || axis > 2) {
    throw std::invalid_argument("make_image_slice: axis " + std::to_string(axis) +
                                " is not 0, 1 or 2");
  }
  if (!std::isfinite(position_m)) {
    throw std::invalid_argument("make_image_slice: position is not finite");
  }
  const int u = axis == 0 ? 1 : 0;
  const int v = axis == 2 ? 1 : 2;
  const double f = (position_m - image.origin_m[axis]) / image.spacing_m[axis];
  const double k = std::clamp(std::round(f), 0.0, static_cast<double>(image.dims[axis] - 1));
  Slice s;
  s.axis = axis;
  s.position_m = image.origin_m[axis] + k * image.spacing_m[axis];
  s.width = image.dims[u];
  s.height = image.dims[v];
  s.origin_m = image.origin_m;
  s.origin_m[axis] = s.position_m;
  s.spacing_m = Eigen::Vector2d(image.spacing_m[u], image.spacing_m[v]);
  s.values.assign(static_cast<std::size_t>(s.width) * s.height, 0.0F);
  return s;
}

// ------------------------------------------------------------------------------------------------
// DeformedVolumeSampler

struct DeformedVolumeSampler::Impl {
  ImageGrid image;
  SamplerOptions options;
  std::vector<MeshState> meshes;
  std::vector<int> order;  // mesh indices by decreasing priority
  std::size_t total_tets = 0;
  std::unordered_map<const void*, OutputState> outputs;
  std::vector<std::uint32_t> tet_stamp;  // scratch for set_displacements
  std::uint32_t stamp = 0;

  void build_mesh(MeshState& m, std::size_t index);
  void update_tet(MeshState& m, int t);
  void place_tet(MeshState& m, int t);
  void recompute_bounds(MeshState& m);
  void apply(std::size_t mesh, std::vector<Vector3d>&& u);
  bool find_in_mesh(const MeshState& m, const Vector3d& p, int& tet, double w[3],
                    bool& inverted) const;
  Location locate(const Vector3d& p) const;
  void plane_candidates(const PlaneGrid& g, int a0, int a1, int b0, int b1,
                        std::vector<TetRef>& out) const;
  void raster_plane(const PlaneGrid& g, int a0, int a1, int b0, int b1,
                    const std::vector<TetRef>& candidates, float* out, std::size_t stride,
                    const float* identity_values);
  std::vector<std::uint64_t> keys;  // scratch of raster_plane
  std::vector<TetRef> scratch_refs;
  std::vector<std::vector<TetRef>> plane_refs;  // scratch of update_volume
  std::vector<int> rank;                        // mesh index -> position in `order`
  Vector3d to_rest(const Vector3d& p) const;
  float sample(const Vector3d& p) const {
    return trilinear(image, to_rest(p).data(), options.outside_value);
  }
  std::uint64_t use_counter = 0;
  OutputState& output(const void* key, bool is_slice, std::uint64_t& token, bool& fresh);
};

void DeformedVolumeSampler::Impl::build_mesh(MeshState& m, std::size_t index) {
  const MeshGeometry& g = m.geo;
  const int nv = static_cast<int>(g.rest_m.size());
  for (int v = 0; v < nv; ++v) {
    if (!finite3(g.rest_m[v])) {
      throw std::invalid_argument(where(g, index) + ": rest vertex " + std::to_string(v) +
                                  " is not finite");
    }
  }
  const std::size_t nt = g.tets.size();
  for (std::size_t t = 0; t < nt; ++t) {
    for (int c = 0; c < 4; ++c) {
      const int v = g.tets[t][c];
      if (v < 0 || v >= nv) {
        throw std::invalid_argument(where(g, index) + ": tetrahedron " + std::to_string(t) +
                                    " has vertex id " + std::to_string(v) + " out of range (" +
                                    std::to_string(nv) + " vertices)");
      }
    }
  }
  m.u.assign(nv, Vector3d::Zero());
  m.u_reported = m.u;
  m.x = g.rest_m;
  m.rest.resize(nt);
  m.rest_sign.resize(nt);
  m.rest_abs_det.resize(nt);
  m.search.resize(nt);
  m.kind.assign(nt, kDegenerate);
  m.identity.assign(nt, 1);
  m.box.assign(nt, Box());
  m.range.assign(nt, CellRange());

  // Vertex -> tetrahedra.
  m.vt_offsets.assign(nv + 1, 0);
  for (const auto& tet : g.tets)
    for (int v : tet) ++m.vt_offsets[v + 1];
  std::partial_sum(m.vt_offsets.begin(), m.vt_offsets.end(), m.vt_offsets.begin());
  m.vt_list.assign(m.vt_offsets.back(), 0);
  {
    std::vector<int> fill(m.vt_offsets.begin(), m.vt_offsets.end() - 1);
    for (std::size_t t = 0; t < nt; ++t)
      for (int v : g.tets[t]) m.vt_list[fill[v]++] = static_cast<int>(t);
  }

  // Rest data and the grid's cell size (mean bounding-box edge of the rest tetrahedra).
  Box rest_bounds;
  double edge_sum = 0.0;
  for (std::size_t t = 0; t < nt; ++t) {
    const auto& tet = g.tets[t];
    const Vector3d& x0 = g.rest_m[tet[0]];
    const Vector3d e1 = g.rest_m[tet[1]] - x0;
    const Vector3d e2 = g.rest_m[tet[2]] - x0;
    const Vector3d e3 = g.rest_m[tet[3]] - x0;
    TetRest& r = m.rest[t];
    for (int a = 0; a < 3; ++a) {
      r.x0[a] = x0[a];
      r.e[3 * a + 0] = e1[a];
      r.e[3 * a + 1] = e2[a];
      r.e[3 * a + 2] = e3[a];
    }
    const double det = e1.dot(e2.cross(e3));
    m.rest_sign[t] = det >= 0.0 ? 1.0 : -1.0;
    m.rest_abs_det[t] = std::abs(det);
    Box b;
    for (int v : tet) b.extend(g.rest_m[v]);
    edge_sum += b.sizes().sum() / 3.0;
    rest_bounds.extend(b);
  }
  Grid& grid = m.grid;
  grid.cells.clear();
  grid.big.clear();
  if (nt == 0) {
    grid.n[0] = grid.n[1] = grid.n[2] = 1;
    grid.cells.assign(1, {});
    grid.domain = Box();
    return;
  }
  double cell = std::max(edge_sum / static_cast<double>(nt) * options.grid_cell_factor, 1e-9);
  // Domain: the rest bounds padded by a quarter of their extent (tissue moves by mm, not by the
  // size of the organ); what leaves it goes to the big list.
  const double pad = 0.25 * rest_bounds.sizes().maxCoeff() + 2.0 * cell;
  Box domain(rest_bounds.min() - Vector3d::Constant(pad),
             rest_bounds.max() + Vector3d::Constant(pad));
  for (;;) {
    long long total = 1;
    for (int a = 0; a < 3; ++a) {
      grid.n[a] = std::max(1, static_cast<int>(std::ceil(domain.sizes()[a] / cell)));
      total *= grid.n[a];
    }
    if (total <= kMaxGridCells) break;
    cell *= 1.25;
  }
  grid.cell_m = cell;
  grid.inv_cell = 1.0 / cell;
  grid.origin = domain.min();
  for (int a = 0; a < 3; ++a) domain.max()[a] = domain.min()[a] + grid.n[a] * cell;
  grid.domain = domain;
  grid.cells.assign(static_cast<std::size_t>(grid.n[0]) * grid.n[1] * grid.n[2], {});
  for (std::size_t t = 0; t < nt; ++t) {
    update_tet(m, static_cast<int>(t));
    place_tet(m, static_cast<int>(t));
  }
  recompute_bounds(m);
}

// Deformed containment data and bounding box of tetrahedron t from m.x.
void DeformedVolumeSampler::Impl::update_tet(MeshState& m, int t) {
  const auto& tet = m.geo.tets[t];
  const Vector3d& x0 = m.x[tet[0]];
  const Vector3d e1 = m.x[tet[1]] - x0;
  const Vector3d e2 = m.x[tet[2]] - x0;
  const Vector3d e3 = m.x[tet[3]] - x0;
  // Inverse of [e1 e2 e3]: rows (e2 x e3, e3 x e1, e1 x e2) / det.
  const Vector3d c0 = e2.cross(e3);
  const Vector3d c1 = e3.cross(e1);
  const Vector3d c2 = e1.cross(e2);
  const double det = e1.dot(c0);
  const auto zero = [&m](int v) { return m.u[v] == Vector3d::Zero(); };
  m.identity[t] =
      static_cast<std::uint8_t>(zero(tet[0]) && zero(tet[1]) && zero(tet[2]) && zero(tet[3]));
  Box b;
  for (int v : tet) b.extend(m.x[v]);
  bool ok = std::isfinite(det) && std::abs(det) > kDegenerateRatio * m.rest_abs_det[t] &&
            std::abs(det) > 0.0 && b.min().allFinite() && b.max().allFinite();
  TetSearch& s = m.search[t];
  if (ok) {
    const double inv_det = 1.0 / det;
    for (int a = 0; a < 3; ++a) {
      s.inv[0 + a] = c0[a] * inv_det;
      s.inv[3 + a] = c1[a] * inv_det;
      s.inv[6 + a] = c2[a] * inv_det;
      s.o[a] = x0[a];
    }
    for (double d : s.inv) ok = ok && std::isfinite(d);
  }
  if (!ok) {
    m.kind[t] = kDegenerate;
    m.box[t] = Box();
    return;
  }
  m.kind[t] = (det > 0.0) == (m.rest_sign[t] > 0.0) ? kPositive : kInverted;
  // Pad so that a point within rounding of a face is inside the box.
  const double pad = 1e-9 * b.sizes().maxCoeff() + 1e-12;
  b.min().array() -= pad;
  b.max().array() += pad;
  m.box[t] = b;
}

// Move tetrahedron t to the grid cells of its current box (only if they changed).
void DeformedVolumeSampler::Impl::place_tet(MeshState& m, int t) {
  Grid& g = m.grid;
  CellRange next;
  if (m.kind[t] != kDegenerate) {
    next.listed = true;
    const Box& b = m.box[t];
    if (!g.domain.contains(b)) {
      next.big = true;
    } else {
      long long count = 1;
      for (int a = 0; a < 3; ++a) {
        next.lo[a] = std::clamp(
            static_cast<int>(std::floor((b.min()[a] - g.origin[a]) * g.inv_cell)), 0, g.n[a] - 1);
        next.hi[a] = std::clamp(
            static_cast<int>(std::floor((b.max()[a] - g.origin[a]) * g.inv_cell)), 0, g.n[a] - 1);
        count *= next.hi[a] - next.lo[a] + 1;
      }
      next.big = count > kMaxCellsPerTet;
    }
  }
  CellRange& cur = m.range[t];
  const auto same = [](const CellRange& a, const CellRange& b) {
    if (a.listed != b.listed || a.big != b.big) return false;
    if (!a.listed || a.big) return true;
    for (int k = 0; k < 3; ++k)
      if (a.lo[k] != b.lo[k] || a.hi[k] != b.hi[k]) return false;
    return true;
  };
  if (same(cur, next)) return;
  const auto for_cells = [&g](const CellRange& r, auto&& fn) {
    for (int k = r.lo[2]; k <= r.hi[2]; ++k)
      for (int j = r.lo[1]; j <= r.hi[1]; ++j)
        for (int i = r.lo[0]; i <= r.hi[0]; ++i) fn(g.cells[g.index(i, j, k)]);
  };
  if (cur.listed) {
    if (cur.big)
      erase_sorted(g.big, t);
    else
      for_cells(cur, [t](std::vector<int>& c) { erase_sorted(c, t); });
  }
  if (next.listed) {
    if (next.big)
      insert_sorted(g.big, t);
    else
      for_cells(next, [t](std::vector<int>& c) { insert_sorted(c, t); });
  }
  cur = next;
}

void DeformedVolumeSampler::Impl::recompute_bounds(MeshState& m) {
  m.bounds = Box();
  for (std::size_t t = 0; t < m.box.size(); ++t)
    if (m.kind[t] != kDegenerate) m.bounds.extend(m.box[t]);
}

// Search mesh m for p: the lowest-index positive tetrahedron containing p, else the
// lowest-index inverted one.
bool DeformedVolumeSampler::Impl::find_in_mesh(const MeshState& m, const Vector3d& p, int& tet,
                                               double w[3], bool& inverted) const {
  if (m.bounds.isEmpty() || !m.bounds.contains(p)) return false;
  const Grid& g = m.grid;
  int best_pos = std::numeric_limits<int>::max();
  int best_inv = std::numeric_limits<int>::max();
  double w_pos[3] = {0, 0, 0}, w_inv[3] = {0, 0, 0};
  const double q[3] = {p[0], p[1], p[2]};
  // Contains = inside the padded box and barycentric test (the rasterizer's rule too).
  const auto test = [&](int t) {
    double wt[3];
    if (!barycentric(m.search[t], q, wt) || !box_contains(m.box[t], q)) return false;
    if (m.kind[t] == kPositive) {
      if (t < best_pos) {
        best_pos = t;
        std::copy(wt, wt + 3, w_pos);
      }
      return true;
    }
    if (t < best_inv) {
      best_inv = t;
      std::copy(wt, wt + 3, w_inv);
    }
    return false;
  };
  for (int t : g.big) test(t);
  if (g.domain.contains(p)) {
    int c[3];
    for (int a = 0; a < 3; ++a)
      c[a] = std::clamp(static_cast<int>(std::floor((p[a] - g.origin[a]) * g.inv_cell)), 0,
                        g.n[a] - 1);
    // Sorted ascending: the first positive hit is the lowest such index in the cell.
    for (int t : g.cells[g.index(c[0], c[1], c[2])]) {
      if (t >= best_pos) break;
      if (test(t)) break;
    }
  }
  if (best_pos != std::numeric_limits<int>::max()) {
    tet = best_pos;
    std::copy(w_pos, w_pos + 3, w);
    inverted = false;
    return true;
  }
  if (best_inv != std::numeric_limits<int>::max()) {
    tet = best_inv;
    std::copy(w_inv, w_inv + 3, w);
    inverted = true;
    return true;
  }
  return false;
}

Location DeformedVolumeSampler::Impl::locate(const Vector3d& p) const {
  Location loc;
  loc.rest_m = p;
  if (!finite3(p)) return loc;
  for (int mi : order) {
    const MeshState& m = meshes[mi];
    int t = -1;
    double w[3];
    bool inv = false;
    if (!find_in_mesh(m, p, t, w, inv)) continue;
    loc.mesh = mi;
    loc.tet = t;
    loc.inverted = inv;
    loc.weights = Eigen::Vector4d(1.0 - w[0] - w[1] - w[2], w[0], w[1], w[2]);
    if (m.identity[t]) {
      loc.rest_m = p;
    } else {
      rest_point(m.rest[t], w, loc.rest_m.data());
    }
    return loc;
  }
  return loc;
}

Vector3d DeformedVolumeSampler::Impl::to_rest(const Vector3d& p) const {
  return locate(p).rest_m;
}

// Tetrahedra whose box meets the plane and the pixel rectangle [a0, a1] x [b0, b1].
void DeformedVolumeSampler::Impl::plane_candidates(const PlaneGrid& g, int a0, int a1, int b0,
                                                   int b1, std::vector<TetRef>& out) const {
  out.clear();
  const int ax = g.axis, ua = g.u_axis(), va = g.v_axis();
  const double ulo = g.origin_u + (a0 - 1) * g.step_u, uhi = g.origin_u + (a1 + 1) * g.step_u;
  const double vlo = g.origin_v + (b0 - 1) * g.step_v, vhi = g.origin_v + (b1 + 1) * g.step_v;
  const auto meets = [&](const Box& b) {
    return g.position >= b.min()[ax] && g.position <= b.max()[ax] && b.max()[ua] >= ulo &&
           b.min()[ua] <= uhi && b.max()[va] >= vlo && b.min()[va] <= vhi;
  };
  for (std::size_t mi = 0; mi < meshes.size(); ++mi) {
    const MeshState& m = meshes[mi];
    if (m.bounds.isEmpty() || !meets(m.bounds)) continue;
    for (std::size_t t = 0; t < m.box.size(); ++t)
      if (m.kind[t] != kDegenerate && meets(m.box[t]))
        out.push_back({static_cast<int>(mi), static_cast<int>(t)});
  }
}

// Samples of the pixels [a0, a1] x [b0, b1] of plane g into out[a + stride * b]: each candidate
// tetrahedron marks the pixels it contains with its key (mesh rank, inverted, index), the
// smallest key wins (the point search's rule, see find_in_mesh), then each pixel is read through
// its winner. Pixels in no tetrahedron read the image at themselves, or identity_values[a +
// stride * b] when given (the volume: the voxel itself).
void DeformedVolumeSampler::Impl::raster_plane(const PlaneGrid& g, int a0, int a1, int b0, int b1,
                                               const std::vector<TetRef>& candidates, float* out,
                                               std::size_t stride, const float* identity_values) {
  constexpr std::uint64_t kNone = std::numeric_limits<std::uint64_t>::max();
  if (a0 > a1 || b0 > b1) return;
  const int w = a1 - a0 + 1;
  keys.assign(static_cast<std::size_t>(w) * (b1 - b0 + 1), kNone);
  const int ua = g.u_axis(), va = g.v_axis();
  double p[3];
  p[g.axis] = g.position;
  for (const TetRef& r : candidates) {
    const MeshState& m = meshes[r.mesh];
    const Box& box = m.box[r.tet];
    const TetSearch& ts = m.search[r.tet];
    int i0, i1, j0, j1;
    index_range(box.min()[ua], box.max()[ua], g.origin_u, g.step_u, g.width, i0, i1);
    index_range(box.min()[va], box.max()[va], g.origin_v, g.step_v, g.height, j0, j1);
    i0 = std::max(i0, a0), i1 = std::min(i1, a1);
    j0 = std::max(j0, b0), j1 = std::min(j1, b1);
    const std::uint64_t key = (static_cast<std::uint64_t>(rank[r.mesh]) << 33) |
                              (static_cast<std::uint64_t>(m.kind[r.tet] == kInverted) << 32) |
                              static_cast<std::uint32_t>(r.tet);
    // Along a row the weights are affine in u: clip the row to where all four may pass (with a
    // wider tolerance, so the clip is a superset), then run the exact test on those pixels.
    const double* inv = ts.inv;
    const double d_axis = g.position - ts.o[g.axis];
    const double g1 = inv[ua], g2 = inv[3 + ua], g3 = inv[6 + ua];
    const double gr[4] = {-(g1 + g2 + g3), g1, g2, g3};
    for (int b = j0; b <= j1; ++b) {
      p[va] = g.origin_v + b * g.step_v;
      const double dv = p[va] - ts.o[va];
      const double c1 = inv[g.axis] * d_axis + inv[va] * dv;
      const double c2 = inv[3 + g.axis] * d_axis + inv[3 + va] * dv;
      const double c3 = inv[6 + g.axis] * d_axis + inv[6 + va] * dv;
      const double c[4] = {1.0 - c1 - c2 - c3, c1, c2, c3};
      double tlo = -std::numeric_limits<double>::infinity();
      double thi = std::numeric_limits<double>::infinity();
      bool empty = false;
      for (int i = 0; i < 4; ++i) {
        // c + gr t >= -eps', t = u - o_u.
        const double lim = -(kBaryEps + 1e-10) - c[i];
        if (gr[i] > 0.0) {
          tlo = std::max(tlo, lim / gr[i]);
        } else if (gr[i] < 0.0) {
          thi = std::min(thi, lim / gr[i]);
        } else if (lim > 0.0) {
          empty = true;
        }
      }
      if (empty || !(tlo <= thi)) continue;
      const double shift = ts.o[ua] - g.origin_u;
      const double alo = std::ceil((tlo + shift) / g.step_u - 1e-6);
      const double ahi = std::floor((thi + shift) / g.step_u + 1e-6);
      const int r0 = static_cast<int>(std::clamp(alo, 1.0 * i0, i1 + 1.0));
      const int r1 = static_cast<int>(std::clamp(ahi, i0 - 1.0, 1.0 * i1));
      std::uint64_t* row = keys.data() + static_cast<std::size_t>(w) * (b - b0) - a0;
      for (int a = r0; a <= r1; ++a) {
        if (key >= row[a]) continue;
        p[ua] = g.origin_u + a * g.step_u;
        double wt[3];
        if (barycentric(ts, p, wt) && box_contains(box, p)) row[a] = key;
      }
    }
  }
  const float outside = options.outside_value;
  for (int b = b0; b <= b1; ++b) {
    p[va] = g.origin_v + b * g.step_v;
    const std::uint64_t* row = keys.data() + static_cast<std::size_t>(w) * (b - b0) - a0;
    float* o = out + stride * b;
    const float* id = identity_values ? identity_values + stride * b : nullptr;
    for (int a = a0; a <= a1; ++a) {
      p[ua] = g.origin_u + a * g.step_u;
      const std::uint64_t key = row[a];
      const MeshState* m = nullptr;
      int t = -1;
      if (key != kNone) {
        m = &meshes[order[key >> 33]];
        t = static_cast<int>(key & 0xffffffffU);
      }
      if (m == nullptr || m->identity[t]) {
        o[a] = id ? id[a] : trilinear(image, p, outside);
        continue;
      }
      double wt[3], x[3];
      barycentric(m->search[t], p, wt);
      rest_point(m->rest[t], wt, x);
      o[a] = trilinear(image, x, outside);
    }
  }
}

// Install new displacements (validated) of one mesh: update the moved tetrahedra's search data
// and grid cells, and tell every tracked output which region changed.
void DeformedVolumeSampler::Impl::apply(std::size_t mi, std::vector<Vector3d>&& u_new) {
  MeshState& m = meshes[mi];
  const double tol = options.move_tolerance_m;
  if (tet_stamp.size() != total_tets) tet_stamp.assign(total_tets, 0);
  if (++stamp == 0) {
    std::fill(tet_stamp.begin(), tet_stamp.end(), 0);
    stamp = 1;
  }
  const std::uint32_t changed_mark = stamp;
  // Tetrahedra touching a changed vertex, and those touching a moved one (reported).
  std::vector<int> changed, moved;
  std::vector<std::uint8_t> vertex_moved(m.u.size(), 0);
  for (std::size_t v = 0; v < m.u.size(); ++v) {
    if (u_new[v] == m.u[v]) continue;
    if (tol <= 0.0 || (u_new[v] - m.u_reported[v]).norm() > tol) {
      vertex_moved[v] = 1;
      m.u_reported[v] = u_new[v];
    }
    for (int k = m.vt_offsets[v]; k < m.vt_offsets[v + 1]; ++k) {
      const int t = m.vt_list[k];
      std::uint32_t& s = tet_stamp[m.tet_offset + t];
      if (s != changed_mark) {
        s = changed_mark;
        changed.push_back(t);
      }
    }
  }
  if (changed.empty()) return;
  // In index order (the per-tetrahedron arrays are then read sequentially).
  if (changed.size() * 8 > m.geo.tets.size()) {
    changed.clear();
    for (std::size_t t = 0; t < m.geo.tets.size(); ++t)
      if (tet_stamp[m.tet_offset + t] == changed_mark) changed.push_back(static_cast<int>(t));
  } else {
    std::sort(changed.begin(), changed.end());
  }
  const std::vector<Vector3d> u_old = std::exchange(m.u, std::move(u_new));
  for (std::size_t v = 0; v < m.u.size(); ++v) m.x[v] = m.geo.rest_m[v] + m.u[v];

  Box dirty;
  for (int t : changed) {
    update_tet(m, t);
    place_tet(m, t);
    bool is_moved = false;
    for (int v : m.geo.tets[t]) is_moved = is_moved || vertex_moved[v];
    if (!is_moved) continue;
    moved.push_back(t);
    // The region the tetrahedron covered and covers (hull of its vertices, degenerate or not).
    for (int v : m.geo.tets[t]) {
      dirty.extend(m.x[v]);
      dirty.extend(Vector3d(m.geo.rest_m[v] + u_old[v]));
    }
  }
  recompute_bounds(m);
  if (moved.empty()) return;
  if (!dirty.isEmpty()) {
    const double pad = tol + 1e-9;
    dirty.min().array() -= pad;
    dirty.max().array() += pad;
  }
  for (auto& [key, out] : outputs) {
    if (!dirty.isEmpty()) out.dirty.extend(dirty);
    if (out.moved.size() != total_tets) out.moved.assign(total_tets, 0);
    for (int t : moved) {
      std::uint8_t& f = out.moved[m.tet_offset + t];
      if (!f) {
        f = 1;
        ++out.moved_count;
      }
    }
  }
}

// The tracking state of the output at `key`; fresh (reset, new token) unless it is the object
// this sampler last updated there (same kind, same token).
OutputState& DeformedVolumeSampler::Impl::output(const void* key, bool is_slice,
                                                 std::uint64_t& token, bool& fresh) {
  static std::atomic<std::uint64_t> next_token{1};
  ++use_counter;
  // Outputs that were dropped without forget(): keep the newest few.
  constexpr std::size_t kKeep = 32;
  if (outputs.size() > kKeep && outputs.find(key) == outputs.end()) {
    std::vector<std::uint64_t> used;
    for (const auto& kv : outputs) used.push_back(kv.second.last_used);
    std::nth_element(used.begin(), used.end() - kKeep / 2, used.end());
    const std::uint64_t cut = *(used.end() - kKeep / 2);
    for (auto it = outputs.begin(); it != outputs.end();)
      it = it->second.last_used < cut ? outputs.erase(it) : std::next(it);
  }
  auto it = outputs.find(key);
  fresh = it == outputs.end() || it->second.is_slice != is_slice || it->second.token != token ||
          token == 0;
  OutputState& out = outputs[key];
  if (fresh) {
    out = OutputState();
    out.is_slice = is_slice;
    out.token = next_token.fetch_add(1);
    token = out.token;
  }
  out.last_used = use_counter;
  return out;
}

DeformedVolumeSampler::DeformedVolumeSampler(ImageGrid image, std::vector<MeshGeometry> meshes,
                                             const SamplerOptions& options)
    : impl_(std::make_unique<Impl>()) {
  image.validate();
  if (!std::isfinite(options.move_tolerance_m) || options.move_tolerance_m < 0.0) {
    throw std::invalid_argument("SamplerOptions: move_tolerance_m must be finite and >= 0");
  }
  if (!std::isfinite(options.grid_cell_factor) || !(options.grid_cell_factor > 0.0)) {
    throw std::invalid_argument("SamplerOptions: grid_cell_factor must be finite and > 0");
  }
  if (!std::isfinite(options.outside_value)) {
    throw std::invalid_argument("SamplerOptions: outside_value must be finite");
  }
  Impl& d = *impl_;
  d.image = std::move(image);
  d.options = options;
  d.meshes.resize(meshes.size());
  for (std::size_t i = 0; i < meshes.size(); ++i) {
    d.meshes[i].geo = std::move(meshes[i]);
    d.meshes[i].tet_offset = d.total_tets;
    d.total_tets += d.meshes[i].geo.tets.size();
    d.build_mesh(d.meshes[i], i);
  }
  d.order.resize(d.meshes.size());
  std::iota(d.order.begin(), d.order.end(), 0);
  std::stable_sort(d.order.begin(), d.order.end(), [&d](int a, int b) {
    return d.meshes[a].geo.priority > d.meshes[b].geo.priority;
  });
  d.rank.resize(d.meshes.size());
  for (std::size_t r = 0; r < d.order.size(); ++r) d.rank[d.order[r]] = static_cast<int>(r);
}

DeformedVolumeSampler::~DeformedVolumeSampler() = default;
DeformedVolumeSampler::DeformedVolumeSampler(DeformedVolumeSampler&&) noexcept = default;
DeformedVolumeSampler& DeformedVolumeSampler::operator=(DeformedVolumeSampler&&) noexcept = default;

std::size_t DeformedVolumeSampler::mesh_count() const { return impl_->meshes.size(); }
const ImageGrid& DeformedVolumeSampler::image() const { return impl_->image; }

const MeshGeometry& DeformedVolumeSampler::mesh(std::size_t index) const {
  if (index >= impl_->meshes.size()) {
    throw std::invalid_argument("DeformedVolumeSampler: no mesh " + std::to_string(index));
  }
  return impl_->meshes[index].geo;
}

int DeformedVolumeSampler::find_mesh(const std::string& id) const {
  for (std::size_t i = 0; i < impl_->meshes.size(); ++i)
    if (impl_->meshes[i].geo.id == id) return static_cast<int>(i);
  return -1;
}

void DeformedVolumeSampler::set_displacements(std::size_t mesh, const float* u_m,
                                              std::size_t count) {
  Impl& d = *impl_;
  if (mesh >= d.meshes.size()) {
    throw std::invalid_argument("set_displacements: no mesh " + std::to_string(mesh) + " (" +
                                std::to_string(d.meshes.size()) + " meshes)");
  }
  const MeshState& m = d.meshes[mesh];
  const std::size_t nv = m.geo.rest_m.size();
  if (count != 3 * nv) {
    throw std::invalid_argument("set_displacements: " + where(m.geo, mesh) + ": " +
                                std::to_string(count) + " floats, expected 3 x " +
                                std::to_string(nv) + " vertices = " + std::to_string(3 * nv));
  }
  if (count > 0 && u_m == nullptr) {
    throw std::invalid_argument("set_displacements: " + where(m.geo, mesh) + ": null data");
  }
  std::vector<Vector3d> u(nv);
  for (std::size_t v = 0; v < nv; ++v) {
    for (int a = 0; a < 3; ++a) {
      const float c = u_m[3 * v + a];
      if (!std::isfinite(c)) {
        throw std::invalid_argument("set_displacements: " + where(m.geo, mesh) + ": vertex " +
                                    std::to_string(v) + " component " + "xyz"[a] +
                                    " is not finite; displacements not applied");
      }
      u[v][a] = c;
    }
  }
  d.apply(mesh, std::move(u));
}

void DeformedVolumeSampler::set_displacements(std::size_t mesh,
                                              const std::vector<Eigen::Vector3d>& u_m) {
  Impl& d = *impl_;
  if (mesh >= d.meshes.size()) {
    throw std::invalid_argument("set_displacements: no mesh " + std::to_string(mesh) + " (" +
                                std::to_string(d.meshes.size()) + " meshes)");
  }
  const MeshState& m = d.meshes[mesh];
  if (u_m.size() != m.geo.rest_m.size()) {
    throw std::invalid_argument("set_displacements: " + where(m.geo, mesh) + ": " +
                                std::to_string(u_m.size()) + " vectors, expected " +
                                std::to_string(m.geo.rest_m.size()) + " (one per vertex)");
  }
  for (std::size_t v = 0; v < u_m.size(); ++v) {
    if (!u_m[v].allFinite()) {
      throw std::invalid_argument("set_displacements: " + where(m.geo, mesh) + ": vertex " +
                                  std::to_string(v) + " is not finite; displacements not applied");
    }
  }
  d.apply(mesh, std::vector<Vector3d>(u_m));
}

const std::vector<Eigen::Vector3d>& DeformedVolumeSampler::displacements(std::size_t mesh) const {
  if (mesh >= impl_->meshes.size()) {
    throw std::invalid_argument("DeformedVolumeSampler: no mesh " + std::to_string(mesh));
  }
  return impl_->meshes[mesh].u;
}

Eigen::Vector3d DeformedVolumeSampler::to_rest(const Eigen::Vector3d& p_m) const {
  return impl_->to_rest(p_m);
}

Location DeformedVolumeSampler::locate(const Eigen::Vector3d& p_m) const {
  return impl_->locate(p_m);
}

float DeformedVolumeSampler::sample(const Eigen::Vector3d& p_m) const { return impl_->sample(p_m); }

ResampleStats DeformedVolumeSampler::update_slice(Slice& slice) {
  Impl& d = *impl_;
  if (slice.axis < 0 || slice.axis > 2) {
    throw std::invalid_argument("update_slice: axis " + std::to_string(slice.axis) +
                                " is not 0, 1 or 2");
  }
  if (slice.width <= 0 || slice.height <= 0) {
    throw std::invalid_argument("update_slice: size " + std::to_string(slice.width) + " x " +
                                std::to_string(slice.height) + " is not positive");
  }
  if (!std::isfinite(slice.position_m) || !slice.origin_m.allFinite() ||
      !slice.spacing_m.allFinite() || !(slice.spacing_m.minCoeff() > 0.0)) {
    throw std::invalid_argument(
        "update_slice: position or origin not finite, or spacing not finite and positive");
  }
  const int axis = slice.axis;
  const int ua = axis == 0 ? 1 : 0;
  const int va = axis == 2 ? 1 : 2;
  const std::size_t total = static_cast<std::size_t>(slice.width) * slice.height;

  bool fresh = false;
  OutputState& out = d.output(&slice, true, slice.sampler_token, fresh);
  const bool same_geometry = !fresh && out.axis == axis && out.position_m == slice.position_m &&
                             out.width == slice.width && out.height == slice.height &&
                             out.origin[ua] == slice.origin_m[ua] &&
                             out.origin[va] == slice.origin_m[va] &&
                             out.spacing == slice.spacing_m && slice.values.size() == total &&
                             out.data == slice.values.data() && out.size == total;
  int a0 = 0, a1 = slice.width - 1, b0 = 0, b1 = slice.height - 1;
  if (same_geometry) {
    // Pixels inside the dirty box (one pixel of margin against rounding).
    const Box& box = out.dirty;
    if (box.isEmpty() || slice.position_m < box.min()[axis] || slice.position_m > box.max()[axis]) {
      a1 = -1;
    } else {
      index_range(box.min()[ua], box.max()[ua], slice.origin_m[ua], slice.spacing_m[0], slice.width,
                  a0, a1);
      index_range(box.min()[va], box.max()[va], slice.origin_m[va], slice.spacing_m[1],
                  slice.height, b0, b1);
    }
  } else {
    slice.values.assign(total, 0.0F);
  }

  ResampleStats stats;
  stats.samples_total = total;
  stats.moved_tets = out.moved_count;
  if (a0 <= a1 && b0 <= b1) {
    PlaneGrid g;
    g.axis = axis;
    g.position = slice.position_m;
    g.origin_u = slice.origin_m[ua];
    g.step_u = slice.spacing_m[0];
    g.origin_v = slice.origin_m[va];
    g.step_v = slice.spacing_m[1];
    g.width = slice.width;
    g.height = slice.height;
    d.plane_candidates(g, a0, a1, b0, b1, d.scratch_refs);
    d.raster_plane(g, a0, a1, b0, b1, d.scratch_refs, slice.values.data(),
                   static_cast<std::size_t>(slice.width), nullptr);
    stats.samples_recomputed = static_cast<std::size_t>(a1 - a0 + 1) * (b1 - b0 + 1);
  }

  out.axis = axis;
  out.position_m = slice.position_m;
  out.width = slice.width;
  out.height = slice.height;
  out.origin = slice.origin_m;
  out.spacing = slice.spacing_m;
  out.data = slice.values.data();
  out.size = total;
  out.dirty = Box();
  if (out.moved_count > 0) std::fill(out.moved.begin(), out.moved.end(), 0);
  out.moved_count = 0;
  return stats;
}

ResampleStats DeformedVolumeSampler::update_volume(ImageGrid& deformed) {
  Impl& d = *impl_;
  const ImageGrid& img = d.image;
  const std::size_t total = img.values.size();
  bool fresh = false;
  OutputState& out = d.output(&deformed, false, deformed.sampler_token, fresh);
  const bool same_geometry =
      !fresh && deformed.dims == img.dims && deformed.origin_m == img.origin_m &&
      deformed.spacing_m == img.spacing_m && deformed.values.size() == total &&
      out.data == deformed.values.data() && out.size == total;
  int lo[3] = {0, 0, 0};
  int hi[3] = {img.dims[0] - 1, img.dims[1] - 1, img.dims[2] - 1};
  if (same_geometry) {
    const Box& box = out.dirty;
    for (int a = 0; a < 3 && !box.isEmpty(); ++a) {
      index_range(box.min()[a], box.max()[a], img.origin_m[a], img.spacing_m[a], img.dims[a], lo[a],
                  hi[a]);
    }
    if (box.isEmpty()) hi[0] = -1;
  } else {
    deformed.dims = img.dims;
    deformed.origin_m = img.origin_m;
    deformed.spacing_m = img.spacing_m;
    deformed.values.assign(total, 0.0F);
  }

  ResampleStats stats;
  stats.samples_total = total;
  stats.moved_tets = out.moved_count;
  if (lo[0] <= hi[0] && lo[1] <= hi[1] && lo[2] <= hi[2]) {
    // The volume is a stack of z planes; each tetrahedron goes to the planes its box spans.
    PlaneGrid g;
    g.axis = 2;
    g.origin_u = img.origin_m[0];
    g.step_u = img.spacing_m[0];
    g.origin_v = img.origin_m[1];
    g.step_v = img.spacing_m[1];
    g.width = img.dims[0];
    g.height = img.dims[1];
    const int planes = hi[2] - lo[2] + 1;
    if (d.plane_refs.size() < static_cast<std::size_t>(planes)) d.plane_refs.resize(planes);
    for (int k = 0; k < planes; ++k) d.plane_refs[k].clear();
    const double ulo = img.origin_m[0] + (lo[0] - 1) * img.spacing_m[0];
    const double uhi = img.origin_m[0] + (hi[0] + 1) * img.spacing_m[0];
    const double vlo = img.origin_m[1] + (lo[1] - 1) * img.spacing_m[1];
    const double vhi = img.origin_m[1] + (hi[1] + 1) * img.spacing_m[1];
    for (std::size_t mi = 0; mi < d.meshes.size(); ++mi) {
      const MeshState& m = d.meshes[mi];
      for (std::size_t t = 0; t < m.box.size(); ++t) {
        if (m.kind[t] == kDegenerate) continue;
        const Box& b = m.box[t];
        if (b.max()[0] < ulo || b.min()[0] > uhi || b.max()[1] < vlo || b.min()[1] > vhi) continue;
        int k0, k1;
        index_range(b.min()[2], b.max()[2], img.origin_m[2], img.spacing_m[2], img.dims[2], k0, k1);
        for (int k = std::max(k0, lo[2]); k <= std::min(k1, hi[2]); ++k)
          d.plane_refs[k - lo[2]].push_back({static_cast<int>(mi), static_cast<int>(t)});
      }
    }
    // Outside every mesh's bounds the volume is the image: copy; rasterize the rest.
    Box all;
    for (const MeshState& m : d.meshes)
      if (!m.bounds.isEmpty()) all.extend(m.bounds);
    int in_lo[2] = {0, 0}, in_hi[2] = {-1, -1};
    if (!all.isEmpty()) {
      for (int a = 0; a < 2; ++a) {
        index_range(all.min()[a], all.max()[a], img.origin_m[a], img.spacing_m[a], img.dims[a],
                    in_lo[a], in_hi[a]);
        in_lo[a] = std::max(in_lo[a], lo[a]);
        in_hi[a] = std::min(in_hi[a], hi[a]);
      }
    }
    const std::size_t plane_size = static_cast<std::size_t>(img.dims[0]) * img.dims[1];
    const auto copy = [&](std::size_t k, int j, int i0, int i1) {
      if (i0 > i1) return;
      const std::size_t at = plane_size * k + static_cast<std::size_t>(img.dims[0]) * j + i0;
      std::copy(img.values.begin() + at, img.values.begin() + at + (i1 - i0 + 1),
                deformed.values.begin() + at);
    };
    for (int k = lo[2]; k <= hi[2]; ++k) {
      const std::vector<TetRef>& refs = d.plane_refs[k - lo[2]];
      const bool raster = !refs.empty() && in_lo[0] <= in_hi[0] && in_lo[1] <= in_hi[1];
      for (int j = lo[1]; j <= hi[1]; ++j) {
        if (!raster || j < in_lo[1] || j > in_hi[1]) {
          copy(k, j, lo[0], hi[0]);
        } else {
          copy(k, j, lo[0], in_lo[0] - 1);
          copy(k, j, in_hi[0] + 1, hi[0]);
        }
      }
      if (!raster) continue;
      g.position = img.origin_m[2] + k * img.spacing_m[2];
      d.raster_plane(g, in_lo[0], in_hi[0], in_lo[1], in_hi[1], refs,
                     deformed.values.data() + plane_size * k, static_cast<std::size_t>(img.dims[0]),
                     img.values.data() + plane_size * k);
    }
    stats.samples_recomputed =
        static_cast<std::size_t>(hi[0] - lo[0] + 1) * (hi[1] - lo[1] + 1) * (hi[2] - lo[2] + 1);
  }
  out.data = deformed.values.data();
  out.size = total;
  out.dirty = Box();
  if (out.moved_count > 0) std::fill(out.moved.begin(), out.moved.end(), 0);
  out.moved_count = 0;
  return stats;
}

void DeformedVolumeSampler::forget(const Slice& slice) { impl_->outputs.erase(&slice); }
void DeformedVolumeSampler::forget(const ImageGrid& deformed) { impl_->outputs.erase(&deformed); }

}  // namespace neurosim::viewer
