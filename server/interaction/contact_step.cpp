// The contact step in named phases (MuJoCo's mj_step habit; State::step, solve_held_poses): pose
// (checks, each station's proxy), history (a relaxing body's step time and history forces),
// candidate triangles, rows, compliance columns, Delassus operator, near field, LCP, forces,
// answer per tool, relaxation, the normals' turn in K (normal_turn), tier post.
//
// Rows: a tool part (the tip sphere, the shaft capsule) against the contactable triangles of each
// body, found on the rest surface once per step (SimulationOptions::contact_geometry_iterations
// = 1; LINEAR only may iterate on the surface its answer deformed; the multirate tiers add their
// latest equilibrium's offset to the depths). Each triangle near the part gives its closest
// point; the rows are
//   - a node row for every triangle vertex inside the part (+ margin): the node against a rigid
//     sphere or capsule (CalculiX's node-to-surface contact with the tool as master), so a tip
//     wider than the triangles feels a patch; its normal the part's where the node, moved along
//     its surface's normal line, leaves the part (merge_features: radial while the centre is in
//     the node's normal cone, turning into the mean normal outside it; the multirate tiers' tip:
//     the same from the point as their latest equilibrium carried it along the mean normal,
//     depth to that point, carried_row_geometry; their shaft: radial within 60 degrees of the
//     mean normal, else the mean normal);
//   - a face row where a triangle's closest point is inside it (normal: the triangle's); with
//     contact_smooth_normals the tip's face rows come from the centre projected along the
//     interpolated node normals (one row where triangles share the projection), no edge rows;
//   - an edge row where every contactable triangle of the edge reports that edge (the distance
//     has a local minimum there; otherwise a neighbouring face row already holds it);
// merged by feature (a vertex seen by its 3-8 triangles, an edge by its two: one row each), and
// two tools on one feature or nearly one constraint share one row (merge_tool_row). With
// contact_spread a row's load is spread over the nodes around its point (spread_row).
// A face row and the node rows of its vertices are nearly dependent when the normals agree, so
// the Delassus operator gets a small compliance in series per row (W_ii (1 + eps),
// SimulationOptions::contact_row_compliance): W stays positive definite and the LCP solution
// unique, the force changes by ~eps relative.
#include "server/interaction/simulation_state.hpp"

#include "common/clock.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <utility>
#include <stdexcept>
#include <string>

namespace neurosim::interaction {

namespace {

using common::Clock;
using common::seconds_since;

// The elements the tier's newest equilibrium holds inverted and under smoothed-tet's element
// barrier, over its bodies.
void count_tier_elements(const TierWorker& tier, std::size_t bodies, StepStats& stats) {
  stats.inverted_elements = 0;
  stats.barrier_elements = 0;
  for (std::size_t bi = 0; bi < bodies; ++bi) {
    const TierLinearization& lin = tier.linearization(static_cast<int>(bi));
    stats.inverted_elements += lin.inverted_elements;
    stats.barrier_elements += lin.barrier_elements;
  }
}

constexpr std::uint64_t kShaftBit = std::uint64_t{1} << 62;
// Feature keys sort vertices, then edges, then faces; the shaft's after the tip's.
std::uint64_t feature_key(bool shaft, TriangleFeature f, std::uint64_t a, std::uint64_t b) {
  return (shaft ? kShaftBit : 0) | (static_cast<std::uint64_t>(f) << 60) | (a << 30) | b;
}
TriangleFeature key_feature(std::uint64_t key) {
  return static_cast<TriangleFeature>((key >> 60) & 3u);
}

// sqrt(d2) <= bound (a norm against a bound), the square root taken only within 1e-9 of the
// bound: the same answer as the norm's, without its cost for the far candidates.
bool norm_at_most(double d2, double bound) {
  if (bound >= 0.0) {
    const double lo = bound * (1.0 - 1e-9), hi = bound * (1.0 + 1e-9);
    if (d2 <= lo * lo) return true;
    if (d2 > hi * hi) return false;
  }
  return std::sqrt(d2) <= bound;
}

// A hit counts when the part's centre c is within reach of the point p (in front of the surface
// or just behind it), or behind the surface there (d . n < 0; n the face's, or the node's rest
// normal) by at most max_penetration with p under c (lateral offset within reach): a tool that
// entered the tissue deeper than its radius still pushes the surface it went through.
bool within(const Vec3& d, const Vec3& n, double reach, double max_penetration_m) {
  if (norm_at_most(d.squaredNorm(), reach)) return true;
  const double h = d.dot(n);
  return h < 0.0 && -h <= max_penetration_m && norm_at_most((d - h * n).squaredNorm(), reach);
}

// Whether a point c of the part's axis (the segment p0-p1; p0 = p1 for the tip) can have a face
// or edge hit on the triangle through x0 (unit normal n): its height h = n . (c - x0) in
// [-behind, reach] and its projection on the plane within reach of the triangle (of the bounding
// circle about the centroid `centre`, radius rho: the largest centroid-vertex distance). A face
// hit needs both (within: in front |d| <= reach, behind -h <= behind and the lateral offset <=
// reach), an edge hit |c - p| <= reach. Exact as a rejection: no hit is lost. With rho = 0 and
// x0 = centre a node (normal n): the node test (within) needs the same.
bool may_touch_face(const Vec3& x0, const Vec3& n, const Vec3& centre, double rho,
                    const Vec3& p0, const Vec3& p1, double reach, double behind) {
  reach *= 1.0 + 1e-9;  // rounding: never reject a hit the exact test would take
  behind *= 1.0 + 1e-9;
  const double h0 = n.dot(p0 - x0), h1 = n.dot(p1 - x0);
  double ta = 0.0, tb = 1.0;
  if (h1 == h0) {
    if (h0 > reach || h0 < -behind) return false;
  } else {
    double lo = (-behind - h0) / (h1 - h0), hi = (reach - h0) / (h1 - h0);
    if (lo > hi) std::swap(lo, hi);
    ta = std::max(0.0, lo);
    tb = std::min(1.0, hi);
    if (ta > tb) return false;
  }
  Vec3 a = p0 + ta * (p1 - p0), b = p0 + tb * (p1 - p0);
  a -= n.dot(a - centre) * n;
  b -= n.dot(b - centre) * n;
  const double lateral2 = (closest_on_segment(centre, a, b) - centre).squaredNorm();
  const double lateral_reach = rho + reach;
  return lateral2 <= lateral_reach * lateral_reach;
}

// Whether the segment p0-p1 comes within `bound` of the point c (a prefilter of may_touch_face
// over a triangle and its vertices: bound = triangle radius + hypot(reach, behind) or more,
// widened by 1e-6 relative, far more than the rounding of either test, so it never rejects what
// they take).
bool may_reach_triangle(const Vec3& c, double bound, const Vec3& p0, const Vec3& p1) {
  bound *= 1.0 + 1e-6;
  return !((c - closest_on_segment(c, p0, p1)).squaredNorm() > bound * bound);
}

// Whether the triangle x (unit normal n) lies wholly to one side of the axis p0-p1, farther than
// reach along s = n x axis (unit): then no point c of the axis has an edge or face hit on it. A
// hit needs |c - p| <= reach (an edge) or the offset of c - p across n within reach (a face, also
// from behind: within), and both are at least |s . (c - p)| = |s . (p0 - p)| (s is normal to the
// axis and to n), linear in p, so over the triangle at least its vertices' least. Exact as a
// rejection (reach widened by 1e-6 relative, far above the rounding of either side); no test
// where the axis is within 1e-6 rad of n. It spares the shaft's alternating projections of the
// triangles beside it that the bounding circle of may_touch_face keeps.
bool beside_axis(const std::array<Vec3, 3>& x, const Vec3& n, const Vec3& p0, const Vec3& p1,
                 double reach) {
  Vec3 s = n.cross(p1 - p0);
  const double s2 = s.squaredNorm();
  if (!(s2 > 1e-12 * (p1 - p0).squaredNorm())) return false;
  s /= std::sqrt(s2);
  const double bound = reach * (1.0 + 1e-6);
  const double a0 = s.dot(x[0] - p0), a1 = s.dot(x[1] - p0), a2 = s.dot(x[2] - p0);
  return (a0 > bound && a1 > bound && a2 > bound) || (a0 < -bound && a1 < -bound && a2 < -bound);
}

// The shaft's points inside the tip sphere are the tip's: its own rows hold them, deeper (with
// SimulationOptions::contact_smooth_normals the two would differ in normal and weights, and the
// shaft, starting at the tip's centre, took most of a 2 mm press's force at a flat face's normal).
bool inside_tip(const Vec3& point, const Vec3& tip_centre, const ToolShape& shape) {
  return (point - tip_centre).norm() < shape.tip_radius_m;
}

// The most loaded nodes whose blocks a body's LoadedBlocks holds (node_displacements): 256 x 256
// blocks of 72 bytes, 4.7 MB reserved, touched only where used.
constexpr int kLoadedNodes = 256;

// The reusable candidate list (State::reusable_candidates) holds for a tool moved by up to this
// many mean surface edges (tip and shaft end): a hand moves the tool by far less per step.
constexpr double kCandidateReuse = 0.25;
// The reusable list's search verdicts (State::search_verdicts) hold for a tool moved by up to
// this many tip radii (tip and shaft end): small against the parts' reach, so they reject nearly
// what the plane tests at the pose itself reject.
constexpr double kSearchReuse = 0.05;

// A row's normal per node as its compliance sees it (m = R^T n in the tiers, n in LINEAR), its
// fixed or weightless nodes marked (slot -1), and sum_k w_k u0_k (the tiers' offset) in offset;
// false if the row rests on fixed nodes only (nothing can move).
bool row_node_normals(Row& r, const TierLinearization* lin, Vec3& offset) {
  const Vec3 n = r.normal;
  double mobile = 0.0;
  for (int k = 0; k < r.nodes; ++k) {
    if (r.slot[k] < 0 || r.w[k] == 0.0) {
      r.slot[k] = -1;  // a fixed node (or no weight): carries nothing
      r.m[k] = n;
      continue;
    }
    mobile += r.w[k];
    if (lin) {
      const Mat3& rot = lin->rotation[r.slot[k]];
      r.m[k] = rot.transpose() * n;
      offset += r.w[k] * lin->offset_m[r.slot[k]];
    } else {
      r.m[k] = n;
    }
  }
  return !(mobile < 1e-6);
}

bool deeper(const Row& a, const Row& b) {
  if (a.depth_m != b.depth_m) return a.depth_m > b.depth_m;
  if (a.body != b.body) return a.body < b.body;
  return a.key < b.key;
}

// A spread's inputs (body, point, normal, radius) as one 64-bit key, of their bits: inputs equal
// bit for bit (find_spread's test) have equal keys.
std::uint64_t spread_key(int body, const Vec3& at, const Vec3& normal, double radius) {
  std::uint64_t h = static_cast<std::uint64_t>(static_cast<std::uint32_t>(body)) * 0x9E3779B97F4A7C15ull;
  auto mix = [&h](double v) {
    std::uint64_t b;
    std::memcpy(&b, &v, sizeof b);
    h = (h ^ b) * 0x100000001B3ull;
    h ^= h >> 29;
  };
  for (int k = 0; k < 3; ++k) mix(at[k]);
  for (int k = 0; k < 3; ++k) mix(normal[k]);
  mix(radius);
  return h;
}

// The least spread radius of a tip row (unit m; SimulationOptions::contact_spread > 0), of the
// rest mesh and the tip alone: 5/3 of the tip's radius R, faded in from nothing at a local edge
// of R / 2 to full at 3/4 R (cells finer than that resolve the tip: their rows sample it). With
// each row's load over about two of the cells the tip covers, no node takes the press alone: the
// bundled 5 mm brain under the 6 mm tip (NONLINEAR, 10 mm) inverted an element 6-7 mm deep with a
// spread of 1-1.5 edges (one node 25-61 % of the press) and held with this floor (the largest
// node 16 %; bench/RESULTS.md, "The tiers' tip rows spread over the tip's footprint"). Lower
// floors bring LINEAR's press there nearer the brain refined under it (1.3 R: 0.2890 N against
// 0.2835) but invert an element in the NONLINEAR press (1.3 R at step 72, 1.5 R at step 86;
// bench/RESULTS.md, "The tip's spread floor against the refined brain and Sneddon").
double tip_spread_floor_m(double edge_m, double tip_radius_m) {
  const double fade = std::clamp((edge_m - 0.5 * tip_radius_m) / (0.25 * tip_radius_m), 0.0, 1.0);
  return (5.0 / 3.0) * tip_radius_m * fade;
}

// A row's feature, tool and body as one key (rows of two geometries or steps compared).
std::uint64_t row_key(const Row& r) {
  return (static_cast<std::uint64_t>(r.tool) << 48) ^ r.key ^
         (static_cast<std::uint64_t>(r.body) << 56);
}

}  // namespace

State::State(const Model& m) {
  bodies_.resize(m.bodies_.size());
  for (std::size_t i = 0; i < m.bodies_.size(); ++i) {
    const BodyModel& b = m.bodies_[i];
    BodyState& bs = bodies_[i];
    bs.columns = std::make_unique<ContactColumns>(*b.body, m.options_.cache_full_field_columns);
    bs.triangle_stamp.assign(b.surface.triangles().size(), -1);
    bs.position_stamp.assign(b.rest_m.size(), -1);
    bs.position_m.assign(b.rest_m.size(), Vec3::Zero());
    bs.force_index.assign(b.rest_m.size(), -1);
    bs.node_tests.assign(4 * b.rest_m.size(), BodyState::NodeTest{});
    bs.sliding_lambda.setZero(b.body->sliding().size());
    if (!b.creep.terms.empty()) {
      bs.history = std::make_unique<ViscoelasticHistory>(b.host_material.viscoelastic, b.creep,
                                                         static_cast<int>(b.rest_m.size()));
      bs.tool_force_n.assign(b.rest_m.size(), Vec3::Zero());
      bs.relax_stamp.assign(b.rest_m.size(), -1);
      bs.history_u_m.assign(b.rest_m.size(), Vec3::Zero());
      bs.history_u_stamp.assign(b.rest_m.size(), -1);
      bs.history_forces_n.assign(b.rest_m.size(), Vec3::Zero());
    }
    if (m.options_.contact_near_field && !b.host_material.viscoelastic.empty()) {
      // One slot per pose index: the scene's tools or the stations (scene ranges), the more.
      const int tools = std::max<int>(64, static_cast<int>(m.tools_.size()));
      bs.near_field_slots = tools;
      bs.near_field_history = std::make_unique<ViscoelasticHistory>(
          b.host_material.viscoelastic, fem::creep_spectrum(b.host_material.viscoelastic), tools);
      bs.near_field_tools.reserve(tools);
      bs.near_field_forces_n.reserve(tools);
      relaxing_near_field_ = true;
    }
    if (m.options_.precompute_contact_columns) {
      const auto t0 = Clock::now();
      std::vector<int> all(b.rest_m.size());
      for (std::size_t s = 0; s < all.size(); ++s) all[s] = static_cast<int>(s);
      bs.columns->ensure(all);
      columns_s_ += seconds_since(t0);
    }
  }
  loaded_blocks_.resize(m.bodies_.size());
  for (std::size_t i = 0; i < m.bodies_.size(); ++i)
    loaded_blocks_[i].reserve(bodies_[i].columns->num_slots(), kLoadedNodes);
  missing_.resize(m.bodies_.size());
  not_ready_stamp_.resize(m.bodies_.size());
  for (std::size_t i = 0; i < m.bodies_.size(); ++i)
    not_ready_stamp_[i].assign(m.bodies_[i].rest_m.size(), -1);
  if (m.options_.column_worker && !m.bodies_.empty()) {
    preload_columns(m);
    std::vector<ColumnWorkerBody> targets;
    for (std::size_t i = 0; i < m.bodies_.size(); ++i)
      targets.push_back({&m.bodies_[i].rest_m, bodies_[i].columns.get(), m.bodies_[i].behind_reach_m});
    for (std::size_t i = 0; i < targets.size(); ++i) {
      // The bound: the budget over one slot's bytes, never below what the preload put in.
      const double per_slot = static_cast<double>(bodies_[i].columns->bytes_per_slot());
      const double budget = m.options_.column_cache_budget_mb * 1e6;
      if (budget > 0.0) {
        targets[i].capacity_slots =
            std::max<std::size_t>(bodies_[i].columns->size() + 2 * CoupledBody::kBlockColumns / 3,
                                  static_cast<std::size_t>(budget / per_slot));
      }
      bodies_[i].capacity_slots = targets[i].capacity_slots;
    }
    ColumnWorkerOptions o;
    o.horizon_s = m.options_.column_horizon_s;
    o.max_tool_speed_m_per_s = m.options_.column_max_tool_speed_m_per_s;
    o.nice = m.options_.column_worker_nice;
    column_worker_ = std::make_unique<ColumnWorker>(std::move(targets), m.tools_, o);
  }
  sliding_active_.assign(m.num_sliding_, 0);
  tier_loads_.resize(m.bodies_.size());
  if (m.tier_ != scene::Tier::kLinear && !m.bodies_.empty()) {
    const auto t0 = Clock::now();
    std::vector<std::unique_ptr<TierEquilibrium>> eq;
    for (const BodyModel& b : m.bodies_) {
      TierEquilibriumDefinition d;
      d.body = b.body.get();
      d.host_material = b.host_material;
      d.host_fixed_nodes = b.host_fixed_nodes;
      d.tier = m.tier_;
      d.newton.tolerance = m.options_.tier_newton_tolerance;
      d.newton.step_limit = m.options_.tier_update_steps;
      // On the worker's thread the updates stay short: refactorizations in the background.
      // Inline (tests, replay) they stay in line: deterministic iterates.
      d.newton.background_refactorization = m.options_.tier_worker_thread;
      try {
        eq.push_back(std::make_unique<TierEquilibrium>(d));
      } catch (const std::exception& ex) {
        throw std::runtime_error(m.source_ + ": mesh " +
                                 m.meshes_[b.body->host_index()].loaded->id + ": " + ex.what());
      }
    }
    // A row loads up to three nodes.
    tier_ = std::make_unique<TierWorker>(
        std::move(eq), m.options_.tier_worker_thread,
        3 * std::max<int>(1, static_cast<int>(m.tools_.size())) *
            m.options_.max_contact_nodes_per_tool);
    tier_s_ = seconds_since(t0);
  }
  // Sliding rows: the step workspace and the inverse of their block at load, not in step 1.
  if (m.num_sliding_ > 0) {
    const auto t0 = Clock::now();
    reserve_workspace(m, std::max<int>(1, static_cast<int>(m.tools_.size())));
    sliding_s_ += seconds_since(t0);
  }
}

void State::reserve_workspace(const Model& m, int tools) {
  const int max_contact = std::max(1, tools * m.options_.max_contact_nodes_per_tool);
  const int max_rows = m.num_sliding_ + max_contact;
  if (max_rows <= lcp_.capacity()) return;
  lcp_.reserve(max_rows);
  w_.setZero(max_rows, max_rows);
  delta_.setZero(max_rows);
  lambda_.setZero(max_rows);
  warm_.assign(max_rows, 0);
  warm_active_.assign(max_rows, 0);
  active_keys_.reserve(max_rows);
  column_terms_.assign(kSpreadNodes * static_cast<std::size_t>(max_contact), LcpColumnTerm{});
  delassus_node_.resize(m.bodies_.size());
  for (std::size_t bi = 0; bi < m.bodies_.size(); ++bi)
    delassus_node_[bi].assign(m.bodies_[bi].rest_m.size(), -1);
  delassus_nodes_.reserve(kSpreadNodes * static_cast<std::size_t>(max_contact));
  delassus_last_row_.reserve(kSpreadNodes * static_cast<std::size_t>(max_contact));
  delassus_row_node_.reserve(max_contact);
  delassus_y_.resize(kSpreadNodes * static_cast<std::size_t>(max_contact) * max_contact);
  delassus_cache_rows_ = 2 * max_contact;
  delassus_cache_.assign(delassus_cache_rows_, DelassusCacheEntry{});
  delassus_cache_content_.assign(delassus_cache_rows_, Row{});
  delassus_cache_node_.resize(m.bodies_.size());
  for (std::size_t bi = 0; bi < m.bodies_.size(); ++bi)
    delassus_cache_node_[bi].assign(m.bodies_[bi].rest_m.size(), -1);
  delassus_cache_nodes_.clear();
  delassus_cache_nodes_.reserve(kDelassusCacheNodes);
  delassus_cache_y_.assign(static_cast<std::size_t>(delassus_cache_rows_) * kDelassusCacheNodes,
                           DelassusY{});
  delassus_row_entry_.reserve(max_contact);
  delassus_row_generation_.reserve(max_contact);
  delassus_node_entry_.reserve(kSpreadNodes * static_cast<std::size_t>(max_contact));
  delassus_prev_entry_.clear();
  delassus_prev_entry_.reserve(max_contact);
  delassus_prev_generation_.clear();
  delassus_prev_generation_.reserve(max_contact);
  delassus_prev_rows_.clear();  // (the cache's sizes follow max_contact)
  delassus_prev_rows_.reserve(max_contact);
  delassus_v_.setZero(max_contact, max_contact);
  delassus_prev_v_.setZero(max_contact, max_contact);
  delassus_match_.reserve(max_contact);
  delassus_fresh_.reserve(max_contact);
  delassus_unmatched_.reserve(max_contact);
  delassus_row_body_.reserve(max_contact);
  delassus_last_fresh_row_.reserve(kSpreadNodes * static_cast<std::size_t>(max_contact));
  delassus_evicted_.assign(m.bodies_.size(), 0);
  spread_memo_.clear();
  spread_memo_.reserve(2 * static_cast<std::size_t>(max_contact));
  spread_prev_memo_.clear();
  spread_prev_memo_.reserve(2 * static_cast<std::size_t>(max_contact));
  spread_keys_.clear();
  spread_keys_.reserve(spread_memo_.capacity());
  spread_prev_keys_.clear();
  spread_prev_keys_.reserve(spread_prev_memo_.capacity());
  rows_.reserve(max_contact);
  row_main_slot_.reserve(max_contact);
  // The sliding rows' block of W is constant: W_A (host, coupled) + W_B (embedded), per body.
  for (const auto& b : m.bodies_) {
    const int o = b.sliding_offset, ns = b.body->sliding().size();
    if (ns == 0) continue;
    w_.block(o, o, ns, ns) = b.body->sliding().compliance();
    for (std::size_t i = 0; i < b.slides.size(); ++i) {
      const auto& sl = *b.slides[i];
      const int f = o + b.slide_first_row[i];
      w_.block(f, f, sl.size(), sl.size()) += sl.compliance();
      for (int k = 0; k < sl.size(); ++k) delta_[f + k] = -sl.pairs()[k].initial_gap_m;
    }
  }
  // Candidates: every triangle at most once per tool and body (a triangle gives at most a face
  // or edge hit and three node hits per tool part).
  std::size_t triangles = 0;
  for (const auto& b : m.bodies_) triangles = std::max(triangles, b.surface.triangles().size());
  hits_.reserve(std::min<std::size_t>(8 * triangles, 8 * 4096));
  boundary_hits_.reserve(hits_.capacity());
  hit_order_.reserve(hits_.capacity());
  sorted_hits_.reserve(hits_.capacity());
  step_candidates_.resize(static_cast<std::size_t>(tools) * bodies_.size());
  for (auto& sc : step_candidates_) {
    sc.triangles.reserve(2 * triangles);
    sc.parts.reserve(2 * triangles);
    sc.nodes.reserve(2 * triangles);
    sc.rest_hits.reserve(hits_.capacity());
    sc.reusable.reserve(triangles);
  }
  tool_rows_.reserve(std::min<std::size_t>(4 * triangles, 4 * 4096));
  tool_order_.reserve(tool_rows_.capacity());
  tool_row_centre_.reserve(tool_rows_.capacity());
  tool_row_plane_.reserve(tool_rows_.capacity());
  tool_row_plane_h_.reserve(tool_rows_.capacity());
  tool_row_fallback_.reserve(tool_rows_.capacity());
  spread_triangles_.reserve(triangles);
  if (tool_rows_memo_.size() < static_cast<std::size_t>(tools)) tool_rows_memo_.resize(tools);
  for (auto& memo : tool_rows_memo_) {
    memo.rows.reserve(static_cast<std::size_t>(m.options_.max_contact_nodes_per_tool));
    memo.spreads.reserve(static_cast<std::size_t>(m.options_.max_contact_nodes_per_tool));
  }
  for (auto& b : bodies_) {
    b.force_slots.reserve(kSpreadNodes * max_rows);
    b.forces_n.reserve(kSpreadNodes * max_rows);
  }
  for (auto& list : missing_) list.reserve(kSpreadNodes * max_rows);
  relax_slots_.reserve(kSpreadNodes * max_rows);
  backup_.resize(bodies_.size());
  for (std::size_t bi = 0; bi < bodies_.size(); ++bi) {
    // A viscoelastic body's forces also hold its history slots: room for every slot.
    const std::size_t most = bodies_[bi].history ? m.bodies_[bi].rest_m.size() : 0;
    bodies_[bi].force_slots.reserve(most);
    bodies_[bi].forces_n.reserve(most);
    backup_[bi].slots.reserve(std::max<std::size_t>(3 * max_rows, most));
    backup_[bi].forces_n.reserve(std::max<std::size_t>(3 * max_rows, most));
    backup_[bi].sliding_lambda.resize(bodies_[bi].sliding_lambda.size());
  }
  sliding_active_backup_.reserve(sliding_active_.size());
  row_keys_.reserve(max_rows);
  own_rows_.reserve(max_contact);
  own_factor_.setZero(max_contact, max_contact);
  own_y_.setZero(max_contact, 3);
  own_z_.assign(max_contact, 0.0);
  turn_v_.assign(max_contact, Vec3::Zero());
  weight_slide_.resize(max_contact);
  weight_slides_.assign(max_contact, 0);
  turn_nodes_.reserve(kSpreadNodes * static_cast<std::size_t>(max_contact));
  turn_u_.resize(kSpreadNodes * static_cast<std::size_t>(max_contact));
  turn_needs_u_.resize(kSpreadNodes * static_cast<std::size_t>(max_contact));
  turn_u_at_.reserve(kSpreadNodes * static_cast<std::size_t>(max_contact));
  turn_u_todo_.reserve(kSpreadNodes * static_cast<std::size_t>(max_contact));
  slide_terms_.reserve(kSpreadNodes * static_cast<std::size_t>(max_contact));
  turn_y_.resize(kSpreadNodes * static_cast<std::size_t>(max_contact));
  turn_a_.resize(kSpreadNodes * static_cast<std::size_t>(max_contact));
  turn_node_.resize(m.bodies_.size());
  for (std::size_t bi = 0; bi < m.bodies_.size(); ++bi)
    turn_node_[bi].assign(m.bodies_[bi].rest_m.size(), -1);
  loaded_force_index_.reserve(kSpreadNodes * static_cast<std::size_t>(max_rows));
  loaded_node_index_.resize(kSpreadNodes * static_cast<std::size_t>(max_contact));
  turn_u_memo_.resize(m.bodies_.size());
  turn_u_memo_stamp_.resize(m.bodies_.size());
  for (std::size_t bi = 0; bi < m.bodies_.size(); ++bi) {
    turn_u_memo_[bi].assign(m.bodies_[bi].rest_m.size(), Vec3::Zero());
    turn_u_memo_stamp_[bi].assign(m.bodies_[bi].rest_m.size(), 0);
  }
  turn_z_.setZero(max_contact, 3);
  previous_row_keys_.reserve(max_rows);
  for (auto& l : tier_loads_) {
    l.slots.reserve(3 * max_rows);
    l.forces_n.reserve(3 * max_rows);
  }
  last_good_.resize(tools);
  for (auto& c : last_good_) c.nodes.reserve(3 * m.options_.max_contact_nodes_per_tool);
  // The inverse of the constant sliding block, once (its size does not depend on the tools).
  if (m.num_sliding_ > 0 && !lcp_constant_block_) {
    lcp_constant_block_ = true;
    if (m.options_.sliding_inactive_set) lcp_.set_constant_block(w_, m.num_sliding_);
  }
}

// Column worker, at load: the columns a first touch needs at once, so it never waits for the
// worker (SimulationOptions::column_preload_budget_mb): all of a body whose columns fit in the
// budget (a small body), else, with rigid openings (the skull's craniotomy), the contact nodes
// within an opening's radius + the widest tool part + the worker's reach of its axis, nearest
// the axis first, while the budget lasts. Allocates; never in a step.
void State::preload_columns(const Model& m) {
  const auto t0 = Clock::now();
  double budget = m.options_.column_preload_budget_mb * 1e6;  // unit byte
  double widest = 0.0;
  for (const ToolShape& t : m.tools_) widest = std::max({widest, t.tip_radius_m, t.shaft_radius_m});
  const double reach =
      widest + m.options_.column_max_tool_speed_m_per_s * m.options_.column_horizon_s;
  std::vector<std::pair<double, int>> near;
  std::vector<int> slots;
  for (std::size_t i = 0; i < m.bodies_.size(); ++i) {
    const BodyModel& b = m.bodies_[i];
    const std::size_t n = b.rest_m.size();
    // A node's columns: L[contact dofs, slot], J_A L[:, slot] and the optional full column.
    double bytes = 8.0 * 3.0 * (3.0 * static_cast<double>(n) + b.body->sliding().size());
    if (m.options_.cache_full_field_columns)
      bytes += 8.0 * 9.0 * static_cast<double>(b.body->host().num_vertices());
    slots.clear();
    if (bytes * static_cast<double>(n) <= budget) {
      for (std::size_t s = 0; s < n; ++s) slots.push_back(static_cast<int>(s));
    } else if (!m.openings_.empty()) {
      near.clear();
      for (std::size_t s = 0; s < n; ++s) {
        double d = std::numeric_limits<double>::infinity();
        for (const auto& o : m.openings_) d = std::min(d, o.radial_m(b.rest_m[s]) - o.radius_m);
        if (d <= reach + b.behind_reach_m) near.emplace_back(d, static_cast<int>(s));
      }
      std::sort(near.begin(), near.end());
      const auto most = static_cast<std::size_t>(budget / bytes);
      for (std::size_t k = 0; k < near.size() && k < most; ++k) slots.push_back(near[k].second);
    }
    bodies_[i].columns->ensure(slots);
    budget -= bytes * static_cast<double>(slots.size());
  }
  columns_s_ += seconds_since(t0);
}

// Phase "pose", first the inputs: nothing changes on a bad pose.
void State::check_poses(const Model& m, const std::vector<ToolPose>& poses) const {
  for (std::size_t t = 0; t < poses.size(); ++t) {
    const auto& p = poses[t];
    if (!p.tip_m.allFinite() || !p.axis.allFinite()) {
      throw std::invalid_argument("Simulation::step: tool " + std::to_string(t) +
                                  " pose is not finite");
    }
    if (p.axis.norm() < 1e-12)
      throw std::invalid_argument("Simulation::step: tool " + std::to_string(t) + " axis is zero");
    if (p.tool < 0 || p.tool >= static_cast<int>(m.tools_.size())) {
      if (!m.tools_.empty() || p.tool != 0) {
        throw std::invalid_argument("Simulation::step: tool " + std::to_string(t) +
                                    " refers to scene tool " + std::to_string(p.tool) + " of " +
                                    std::to_string(m.tools_.size()));
      }
    }
    // One pose per station and step (each station's proxy moves once).
    if (p.station < -1 || p.station >= kMaxStations) {
      throw std::invalid_argument("Simulation::step: tool " + std::to_string(t) + " station " +
                                  std::to_string(p.station) + " is outside [-1, " +
                                  std::to_string(kMaxStations) + ")");
    }
    const int key = p.station >= 0 ? p.station : static_cast<int>(t);
    for (std::size_t u = 0; u < t; ++u) {
      const int other = poses[u].station >= 0 ? poses[u].station : static_cast<int>(u);
      if (other == key) {
        throw std::invalid_argument("Simulation::step: tools " + std::to_string(u) + " and " +
                                    std::to_string(t) + " are both station " +
                                    std::to_string(key));
      }
    }
  }
}

void State::begin_step(const Model& m, int tools, StepStats& stats) {
  reserve_workspace(m, tools);
  ++step_counter_;
  candidate_tests_ = 0;
  stats.tier_updated = false;
  stats.tier_update_us = 0.0;
  stats.inverted_elements = 0;
  stats.barrier_elements = 0;
  if (tier_) {
    tier_->begin_step();
    count_tier_elements(*tier_, bodies_.size(), stats);
  }
  rows_.clear();
}

// Position of a contact slot's node on the surface deformed by this step's answer so far
// (LINEAR): rest + sum_k L(slot, k) f_k over the loaded slots (cached columns). Computed once per
// geometry and slot.
const mesh::Vec3& State::position(const Model& m, int body, int slot) {
  BodyState& bs = bodies_[body];
  if (bs.position_stamp[slot] == geometry_counter_) return bs.position_m[slot];
  bs.position_stamp[slot] = geometry_counter_;
  const BodyModel& b = m.bodies_[body];
  Vec3 x = b.rest_m[slot];
  for (std::size_t k = 0; k < bs.force_slots.size(); ++k)
    x.noalias() += bs.columns->block(slot, bs.force_slots[k]) * bs.forces_n[k];
  bs.position_m[slot] = x;
  return bs.position_m[slot];
}

// Phase "candidate triangles": of one body near one tool (rest grid, widened by the larger of
// the surface's largest displacement in this geometry and behind_reach_m), each listed once. Found once per step and tool: the
// later geometries of the step reuse the list unless their displacement needs a wider one.
// On the rest surface (no force on the body: LINEAR's one geometry per step) the list is made
// from reusable candidates (reusable_candidates), found again only when the tool moved farther.
void State::candidate_triangles(const Model& m, int body, int tool, const ToolPose& pose,
                                const Vec3& axis) {
  const BodyModel& b = m.bodies_[body];
  BodyState& bs = bodies_[body];
  const ToolShape& shape = m.tools_[pose.tool];
  // The surface may have moved by this geometry's displacement, and a tool may push a surface it
  // is up to behind_reach below (the same box whatever came before: the rows are the pose's).
  const double moved = std::max(bs.max_displacement_m, b.behind_reach_m);
  const double slack = m.options_.candidate_margin * shape.tip_radius_m + moved;
  StepCandidates& sc = step_candidates_[tool * bodies_.size() + body];
  candidates_ = &sc;
  if (sc.step != step_counter_) {
    sc.step = step_counter_;
    sc.rest_hits_valid = false;
  } else if (sc.slack_m >= slack && sc.moved_m >= bs.max_displacement_m &&
             !(sc.rest_only && !bs.force_slots.empty())) {
    return;  // a list found with at least this slack holds every triangle this geometry reaches
  }
  sc.slack_m = slack;
  // A hit is a point of the deformed triangle (within `moved` of its rest point) within reach of
  // the part's centre, or with the centre behind it by at most `behind` and laterally within
  // reach: at most sqrt(reach^2 + behind^2) from the centre. A quarter more than this geometry's
  // displacement, so the step's next geometries mostly keep the list.
  sc.moved_m = 1.25 * bs.max_displacement_m;
  const Vec3 p0 = pose.tip_m, p1 = pose.tip_m + shape.shaft_length_m * axis;
  // The rest surface (no force on the body): flat rows, and the smooth tip's (its flat_distance
  // reads the list: reusable_candidates keeps every triangle nearer the tip than its row's height).
  sc.rest_only = sc.moved_m == 0.0 && bs.force_slots.empty();
  if (sc.rest_only) {
    rest_candidate_list(m, body, pose.tool, p0, p1, slack, sc);
    return;
  }
  full_candidate_list(m, body, pose.tool, p0, p1, slack, sc);
}

// Phase "candidate triangles" on the rest surface (StepCandidates::rest_only): this pose's list
// from the reusable candidates (reusable_candidates, made again once the tip or the shaft end
// moved more than kCandidateReuse mean edges) and their search verdicts (search_verdicts, made
// again past kSearchReuse tip radii); the last list kept while the grid query's cells are the
// same. p0, p1: the tip's centre and the shaft's end, slack the box's widening, unit m.
void State::rest_candidate_list(const Model& m, int body, int tool_index, const Vec3& p0,
                                const Vec3& p1, double slack, StepCandidates& sc) {
  const BodyModel& b = m.bodies_[body];
  const ToolShape& shape = m.tools_[tool_index];
  const bool has_shaft = shape.shaft_radius_m > 0.0 && shape.shaft_length_m > 0.0;
  std::vector<int>& list = sc.triangles;
  const double reuse_m = kCandidateReuse * b.surface.mean_edge_m();
  bool keep = sc.list_valid;  // the last list of the reusable candidates and verdicts
  if (!sc.reuse_valid || sc.reuse_tool != tool_index || sc.reuse_slack_m != slack ||
      (p0 - sc.reuse_p0).norm() > reuse_m || (p1 - sc.reuse_p1).norm() > reuse_m) {
    reusable_candidates(m, body, tool_index, p0, p1, slack, reuse_m, sc);
    keep = false;
  }
  const double search_m = kSearchReuse * shape.tip_radius_m;
  if (!sc.search_valid || sc.search_m != search_m || (p0 - sc.search_p0).norm() > search_m ||
      (p1 - sc.search_p1).norm() > search_m) {
    search_verdicts(m, body, p0, p1, search_m, sc);
    keep = false;
  }
  // This pose's list: the reusable candidates its grid query lists, in the query's order (the
  // tip's box, then the shaft's), so a node's hit sums its triangles' normals in the same
  // order as the full search's list (the answer does not depend on where the list was found).
  const auto tip_cells = b.surface.query_cells(p0 - Vec3::Constant(shape.tip_radius_m + slack),
                                               p0 + Vec3::Constant(shape.tip_radius_m + slack));
  PointGrid::CellRange shaft_cells;
  if (has_shaft) {
    const double reach = shape.shaft_radius_m + slack;
    shaft_cells = b.surface.query_cells(p0.cwiseMin(p1) - Vec3::Constant(reach),
                                        p0.cwiseMax(p1) + Vec3::Constant(reach));
  }
  // The same cells list the same candidates (a tool moved by a few micrometres per step).
  auto same = [](const PointGrid::CellRange& a, const PointGrid::CellRange& c) {
    for (int k = 0; k < 3; ++k)
      if (a.lo[k] != c.lo[k] || a.hi[k] != c.hi[k]) return false;
    return true;
  };
  if (keep && same(tip_cells, sc.list_tip_cells) && same(shaft_cells, sc.list_shaft_cells))
    return;
  list.clear();
  sc.parts.clear();
  sc.nodes.clear();
  sc.list_valid = true;
  sc.list_tip_cells = tip_cells;
  sc.list_shaft_cells = shaft_cells;
  // (a part with neither a search nor a node that can be hit is not searched at all)
  auto parts = [](const StepCandidates::Reusable& c) {
    int searched = 0;
    for (int part = 0; part < 2; ++part)
      if ((c.search & (1 << part)) || ((c.nodes >> (3 * part)) & 7)) searched |= 1 << part;
    return static_cast<std::uint8_t>((c.parts & searched) | (c.search << 2) |
                                     StepCandidates::kSearchKnown);
  };
  for (const auto& c : sc.reusable)
    if (ContactSurface::listed_cell(tip_cells, c.cell)) {
      list.push_back(c.triangle);
      sc.parts.push_back(parts(c));
      sc.nodes.push_back(c.nodes);
    }
  if (has_shaft)
    for (const auto& c : sc.reusable)
      if (!ContactSurface::listed_cell(tip_cells, c.cell) &&
          ContactSurface::listed_cell(shaft_cells, c.cell)) {
        list.push_back(c.triangle);
        sc.parts.push_back(parts(c));
        sc.nodes.push_back(c.nodes);
      }
}

// Phase "candidate triangles" on a deformed surface (or a body carrying a force): the rest
// grid's boxes about the tip and the shaft, each triangle kept once and only where its rest
// bounding sphere can reach a part (with the parts it can reach). Unit m.
void State::full_candidate_list(const Model& m, int body, int tool_index, const Vec3& p0,
                                const Vec3& p1, double slack, StepCandidates& sc) {
  const BodyModel& b = m.bodies_[body];
  BodyState& bs = bodies_[body];
  const ToolShape& shape = m.tools_[tool_index];
  const bool has_shaft = shape.shaft_radius_m > 0.0 && shape.shaft_length_m > 0.0;
  std::vector<int>& list = sc.triangles;
  sc.list_valid = false;
  list.clear();
  sc.parts.clear();
  sc.nodes.clear();
  auto bound = [&](double radius) {
    const double reach = radius + m.options_.candidate_margin * shape.tip_radius_m;
    const double behind = std::max(reach, b.behind_reach_m);
    return std::sqrt(reach * reach + behind * behind) + sc.moved_m;
  };
  const double tip_bound = bound(shape.tip_radius_m), shaft_bound = bound(shape.shaft_radius_m);
  const long long stamp = ++stamp_counter_;
  b.surface.query(p0 - Vec3::Constant(shape.tip_radius_m + slack),
                  p0 + Vec3::Constant(shape.tip_radius_m + slack), list);
  if (has_shaft) {
    // (only the cells near the axis: a kept triangle's centroid is within its radius plus the
    // larger of the tests' reaches below of the axis, the tip's centre being on it)
    const double reach = shape.shaft_radius_m + slack;
    b.surface.query_near(p0.cwiseMin(p1) - Vec3::Constant(reach),
                         p0.cwiseMax(p1) + Vec3::Constant(reach), p0, p1,
                         std::max(shape.tip_radius_m, shape.shaft_radius_m) + slack, list);
  }
  // Keep each triangle once, and only those whose rest bounding sphere can reach a tool part;
  // per triangle, the parts it can reach. A part's hits (a node, an edge or face point) lie
  // within its bound of the part (within(): sqrt(reach^2 + behind^2), the surface moved by at
  // most `moved`), so a triangle whose rest bounding sphere is farther from a part than its bound
  // has none of that part's hits: not even a node hit found from a neighbour, which would add
  // this triangle's normal (the node is a vertex of it, within its radius of the centroid).
  constexpr double kRound = 1.0 + 1e-9;  // never skip a part the exact tests would take
  std::size_t kept = 0;
  for (std::size_t k = 0; k < list.size(); ++k) {
    const int t = list[k];
    if (bs.triangle_stamp[t] == stamp) continue;
    bs.triangle_stamp[t] = stamp;
    const Vec3& c = b.surface.centroid(t);
    const double radius = b.surface.radius_m(t);
    const double to_tip2 = (c - p0).squaredNorm();
    const bool tip = norm_at_most(to_tip2, std::min(shape.tip_radius_m + slack, tip_bound) + radius);
    bool shaft = false;
    double to_axis2 = std::numeric_limits<double>::infinity();
    if (has_shaft) {
      to_axis2 = (c - closest_on_segment(c, p0, p1)).squaredNorm();
      shaft = norm_at_most(to_axis2, std::min(shape.shaft_radius_m + slack, shaft_bound) + radius);
    }
    if (!(tip || shaft)) continue;
    list[kept++] = t;
    sc.parts.push_back(static_cast<std::uint8_t>(
        (norm_at_most(to_tip2, (tip_bound + radius) * kRound) ? 1 : 0) |
        (norm_at_most(to_axis2, (shaft_bound + radius) * kRound) ? 2 : 0)));
  }
  list.resize(kept);
}

// Phase "candidate triangles" on the rest surface, the reusable list: the triangles on which a
// part of a tool at p0-p1 moved by at most reuse_m can have a hit (a vertex inside the part, an
// edge or face point: may_touch_face of the triangle and of each mobile vertex with its normal,
// reach and behind widened by reuse_m: a point of the moved part is within reuse_m of the point
// of this part at the same place along it), with those parts, in the grid's order. Any other
// triangle gives a moved part no hit and adds no normal to a node's hit, so searching these in
// the list's order finds the full search's hits. With SimulationOptions::contact_smooth_normals
// also (no part: no hit) every triangle whose rest bounding sphere is within the tip's flat bound
// of the moved tip: flat_distance's minimum, below a tip face row's height (at most the tip's reach,
// or behind_reach behind the surface), is over these, and a listed triangle not in the full
// search's list is farther from the tip than that bound (its sphere test, at least the bound, failed),
// so the minimum is the full list's. Allocates nothing (reserved).
void State::reusable_candidates(const Model& m, int body, int tool_index, const Vec3& p0,
                                const Vec3& p1, double slack, double reuse_m, StepCandidates& sc) {
  const BodyModel& b = m.bodies_[body];
  const ToolShape& shape = m.tools_[tool_index];
  const bool has_shaft = shape.shaft_radius_m > 0.0 && shape.shaft_length_m > 0.0;
  const double w = reuse_m * (1.0 + 1e-6);  // the moved pose, with room for rounding
  auto& found = sc.triangles;  // scratch (reserved: two queries' worth); the caller refills it
  found.clear();
  // The tip's box and the shaft's box near its axis, each triangle once, in rank order, less
  // those whose rest bounding sphere is beyond every test below: reusable_parts' sphere-capsule
  // tests (may_reach_triangle: centroid within radius + hypot(reach, back) of the tip's centre
  // or the axis, widened by 1e-6) and the flat bound (radius + back of the tip's centre, within
  // the first), the tip's centre being on the axis; 1e-9 more for the rounding of the distances.
  const double margin = m.options_.candidate_margin * shape.tip_radius_m;
  auto reach_and_back = [&](double radius) {
    const double reach = radius + margin + w;
    return std::hypot(reach, std::max(reach, b.behind_reach_m + w));
  };
  const double near = has_shaft ? std::max(reach_and_back(shape.tip_radius_m),
                                           reach_and_back(shape.shaft_radius_m))
                                : reach_and_back(shape.tip_radius_m);
  const double tip_box = shape.tip_radius_m + slack + w;
  const double reach = shape.shaft_radius_m + slack + w;
  const Vec3& end = has_shaft ? p1 : p0;
  b.surface.query_tool(p0 - Vec3::Constant(tip_box), p0 + Vec3::Constant(tip_box), has_shaft,
                       p0.cwiseMin(p1) - Vec3::Constant(reach),
                       p0.cwiseMax(p1) + Vec3::Constant(reach), p0, end, near,
                       near * (1.0 + 1e-9), found);
  sc.reusable.clear();
  candidate_tests_ += static_cast<int>(found.size());
  for (const int rank : found) {
    const int t = b.surface.ranked_triangle(rank);
    bool flat = false;  // within reach of flat_distance (the smooth tip's)
    const int parts = reusable_parts(m, body, t, shape, p0, p1, w, flat);
    if (parts != 0 || flat)
      sc.reusable.push_back(
          {t, rank, static_cast<std::uint8_t>(parts), b.surface.query_cell(t)});
  }
  // (in rank order: the grid's, as query_tool lists them)
  sc.reuse_valid = true;
  sc.reuse_tool = tool_index;
  sc.reuse_slack_m = slack;
  sc.reuse_p0 = p0;
  sc.reuse_p1 = p1;
  sc.search_valid = false;
  sc.list_valid = false;  // (its triangles were the scratch above)
}

// reusable_candidates, one triangle t: the parts of a tool at p0-p1 moved by at most w (unit m)
// that can have a hit on it (bit 0 the tip, 1 the shaft; a vertex inside the part, an edge or
// face point: may_touch_face of the triangle and of each mobile vertex with its normal, reach and
// behind widened by w); with SimulationOptions::contact_smooth_normals and no part, `flat`: the
// triangle's rest bounding sphere is within the tip's flat bound of the moved tip.
int State::reusable_parts(const Model& m, int body, int t, const ToolShape& shape,
                          const Vec3& p0, const Vec3& p1, double w, bool& flat) const {
  const BodyModel& b = m.bodies_[body];
  const bool has_shaft = shape.shaft_radius_m > 0.0 && shape.shaft_length_m > 0.0;
  const double margin = m.options_.candidate_margin * shape.tip_radius_m;
  const double behind = b.behind_reach_m;
  const std::vector<Vec3>& normals = b.body->contact_normals();
  const auto& x = b.surface.rest_vertices(t);
  const auto& slots = b.surface.triangles()[t].slot;
  int parts = 0;
  for (int part = 0; part < (has_shaft ? 2 : 1); ++part) {
    const Vec3& q1 = part == 1 ? p1 : p0;
    const double reach = (part == 1 ? shape.shaft_radius_m : shape.tip_radius_m) + margin + w;
    const double back = std::max(reach, behind + w);
    // Sphere against capsule first (most of the boxes' triangles are far from the part): a
    // face or edge hit needs a point c of the axis within radius + reach laterally of the
    // centroid and within back in height of the triangle's plane (may_touch_face: |c - centroid|
    // <= hypot(radius + reach, back)), a node hit c within reach laterally and back in height of
    // the vertex (|c - vertex| <= hypot(reach, back), so |c - centroid| <= radius + hypot(reach,
    // back), the larger bound): beyond it every test below fails.
    if (!may_reach_triangle(b.surface.centroid(t), b.surface.radius_m(t) + std::hypot(reach, back),
                            p0, q1))
      continue;
    bool may = may_touch_face(x[0], b.surface.rest_normal(t), b.surface.centroid(t),
                              b.surface.radius_m(t), p0, q1, reach, back);
    for (int k = 0; k < 3 && !may; ++k)
      may = slots[k] >= 0 && may_touch_face(x[k], normals[slots[k]], x[k], 0.0, p0, q1, reach, back);
    if (may) parts |= 1 << part;
  }
  flat = false;
  if (parts == 0 && m.options_.contact_smooth_normals) {
    const double reach = shape.tip_radius_m + margin + w;
    const double back = std::max(reach, behind + w);
    flat = norm_at_most((b.surface.centroid(t) - p0).squaredNorm(),
                        (b.surface.radius_m(t) + back) * (1.0 + 1e-9));
  }
  return parts;
}

// Phase "candidate triangles" on the rest surface, the reusable list's search verdicts: per
// listed triangle and part, whether the part's edge or face search can find a hit on it while
// the tip and shaft end stay within search_m of p0 / p1 (Reusable::search). These are
// part_features' plane tests (may_reach_triangle, may_touch_face, beside_axis) with reach and
// behind widened by search_m: a point c' of the moved axis is within search_m of the point c of
// this axis at the same place along it, so a hit at c' (|c' - p| <= reach, or a height in
// [-behind, reach] with the lateral offset within reach) has c within the widened bounds, and
// |s . (c - p)| <= reach + search_m for beside_axis's s (normal to this axis and the
// triangle's). Exact as rejections, as the tests at the pose are; a part without a search
// verdict skips its edge and face search, a part with one skips the tests at the pose (the
// search finds no hit where they would have rejected). Node tests are not affected.
// The smooth tip (SimulationOptions::contact_smooth_normals) also: kNoProjection where its
// projection along the interpolated normals (project_along_normals) can give no hit, so the
// flat fallback follows at once. A hit there is a point y of the triangle with the centre
// x = y + d, d along N(y) = sum b_k n_k (up to Newton's residual, at most 1e-9 of the
// triangle's size) and |d| <= sqrt(reach^2 + behind^2) (within); the in-plane part of d is at
// most |d| T with T = max_k |n_k in-plane| / min_k (n_k . n) (N's in-plane part at most the
// largest node's, N . n at least the least), so x's foot on the plane is within |d| T of the
// triangle, and the moved x's within |d| T + search_m. Farther: no projection hit (not tested
// where some n_k . n <= 0).
// And per part and vertex (Reusable::nodes) whether the vertex can be the part's node hit: the
// node test's may_touch_face (reach and behind widened by search_m, a node is its own circle),
// as reusable_candidates makes it; a function of the node alone, so every triangle of a node
// that can be hit still tests it and adds its normal to the hit.
void State::search_verdicts(const Model& m, int body, const Vec3& p0, const Vec3& p1,
                            double search_m, StepCandidates& sc) {
  const BodyModel& b = m.bodies_[body];
  const ToolShape& shape = m.tools_[sc.reuse_tool];
  const double w = search_m * (1.0 + 1e-6);  // the moved pose, with room for rounding
  const double margin = m.options_.candidate_margin * shape.tip_radius_m;
  const bool smooth = m.options_.contact_smooth_normals;
  const std::vector<Vec3>& normals = b.body->contact_normals();
  for (auto& c : sc.reusable) {
    c.search = 0;
    c.nodes = 0;
    const int t = c.triangle;
    const auto& slots = b.surface.triangles()[t].slot;
    for (int part = 0; part < 2; ++part) {
      if (!(c.parts & (1 << part))) continue;
      const Vec3& q1 = part == 1 ? p1 : p0;
      const double reach = (part == 1 ? shape.shaft_radius_m : shape.tip_radius_m) + margin;
      const double behind = std::max(reach, b.behind_reach_m);
      const auto& x = b.surface.rest_vertices(t);
      for (int k = 0; k < 3; ++k)
        if (slots[k] >= 0 &&
            may_touch_face(x[k], normals[slots[k]], x[k], 0.0, p0, q1, reach + w, behind + w))
          c.nodes |= static_cast<std::uint8_t>(1 << (3 * part + k));
    }
    const Vec3& n = b.surface.rest_normal(t);
    if (n.isZero(0.0)) continue;  // degenerate: never searched (triangle_features)
    for (int part = 0; part < 2; ++part) {
      if (!(c.parts & (1 << part))) continue;
      const bool shaft = part == 1;
      const Vec3& q1 = shaft ? p1 : p0;
      // part_features' reach and behind, widened
      const double reach = (shaft ? shape.shaft_radius_m : shape.tip_radius_m) + margin;
      const double behind = std::max(reach, b.behind_reach_m);
      const Vec3& centre = b.surface.centroid(t);
      const double rho = b.surface.radius_m(t);
      if (!may_reach_triangle(centre, rho + reach + behind + 2.0 * w, p0, q1) ||
          !may_touch_face(b.surface.rest_vertices(t)[0], n, centre, rho, p0, q1, reach + w,
                          behind + w) ||
          (shaft && beside_axis(b.surface.rest_vertices(t), n, p0, p1, reach + w)))
        continue;
      c.search |= static_cast<std::uint8_t>(1 << part);
      if (!shaft && smooth) {
        const auto& x = b.surface.rest_vertices(t);
        const auto& nn = b.surface.node_normals(t);
        double tilt = 0.0, least = std::numeric_limits<double>::infinity();
        for (int k = 0; k < 3; ++k) {
          const double a = nn[k].dot(n);
          least = std::min(least, a);
          tilt = std::max(tilt, (nn[k] - a * n).norm());
        }
        if (!(least > 0.0)) continue;
        const double d = std::sqrt(reach * reach + behind * behind);
        const double bound = (d * tilt / least + w) * (1.0 + 1e-6) + 1e-6 * rho;
        const Vec3 foot = p0 - n.dot(p0 - x[0]) * n;
        if ((closest_on_triangle(foot, x).point_m - foot).squaredNorm() > bound * bound)
          c.search |= StepCandidates::Reusable::kNoProjection;
      }
    }
  }
  sc.search_valid = true;
  sc.search_m = search_m;
  sc.search_p0 = p0;
  sc.search_p1 = p1;
}

// triangle_features' step: triangle t's positions x, unit normal n, centroid and radius (m),
// deformed (the host's positions, into moved) or at rest (the surface's own values); false for
// a degenerate triangle (never searched).
bool State::triangle_geometry(const Model& m, int body, int t, bool deformed,
                              std::array<Vec3, 3>& moved, const std::array<Vec3, 3>*& x, Vec3& n,
                              Vec3& centre, double& rho) {
  const BodyModel& b = m.bodies_[body];
  if (deformed) {
    const SurfaceTriangle& tri = b.surface.triangles()[t];
    const auto& rest = b.body->contact_mesh().vertices();
    for (int k = 0; k < 3; ++k)
      moved[k] = tri.slot[k] >= 0 ? position(m, body, tri.slot[k]) : rest[tri.node[k]];
    x = &moved;
    n = (moved[1] - moved[0]).cross(moved[2] - moved[0]);
    if (!(n.norm() > 0.0)) return false;
    n.normalize();
    centre = (moved[0] + moved[1] + moved[2]) / 3.0;
    double rho2 = 0.0;
    for (int k = 0; k < 3; ++k) rho2 = std::max(rho2, (moved[k] - centre).squaredNorm());
    rho = std::sqrt(rho2);
    return true;
  }
  n = b.surface.rest_normal(t);
  if (n.isZero(0.0)) return false;  // degenerate
  centre = b.surface.centroid(t);
  rho = b.surface.radius_m(t);
  return true;
}

// Phase "rows", geometry: the closest features of the deformed candidate triangles to the tip
// centre and to the shaft axis, within the part's radius + margin.
void State::triangle_features(const Model& m, int body, int tool, const ToolPose& pose,
                              const Vec3& axis) {
  const BodyModel& b = m.bodies_[body];
  const ToolShape& shape = m.tools_[pose.tool];
  const double margin = m.options_.candidate_margin * shape.tip_radius_m;
  const bool has_shaft = shape.shaft_radius_m > 0.0 && shape.shaft_length_m > 0.0;
  const Vec3 p0 = pose.tip_m, p1 = pose.tip_m + shape.shaft_length_m * axis;
  const auto& tris = b.surface.triangles();
  // The multirate tiers' latest equilibrium (u* per contact slot), where their node tests take
  // the tip's nodes too (node_hits).
  const TierLinearization* lin =
      tier_ && !tier_->linearization(body).displacement_m.empty() ? &tier_->linearization(body)
                                                                   : nullptr;
  // The deformed surface, and the rest surface too once the body carries a force: the LCP's
  // depths are taken from rest, so a feature that penetrates at rest is a row even when the last
  // answer moved it out of reach (a tool leaving faster than the margin would otherwise lose the
  // tissue for a step, then find it again: chatter).
  // The multirate tiers find their rows on the rest surface only: their equilibrium lags the
  // step (worker thread), and a row set that followed it would keep the held force from settling
  // (the step and the updates are a fixed-point iteration on fixed rows).
  // LINEAR: the step's first geometry is the rest surface (no force yet); its hits are kept and
  // stand for the rest surface's in the later geometries.
  StepCandidates& sc = step_candidates_[tool * bodies_.size() + body];
  const int g_first = tier_ ? 1 : 0;
  int g_last = tier_ || bodies_[body].max_displacement_m > 0.0 ? 1 : 0;
  hits_.clear();
  const bool first_is_rest = !tier_ && !sc.rest_hits_valid && g_last == 0;
  if (!tier_ && sc.rest_hits_valid && g_last == 1) {
    hits_.assign(sc.rest_hits.begin(), sc.rest_hits.end());
    g_last = 0;
  }
  BodyState& bs = bodies_[body];
  const long long memo = ++node_memo_counter_;  // each node tested once per geometry and part
  // With no force on the body every geometry is the rest surface (LINEAR's one geometry per
  // step, the tiers' rows): its vertices, normal, centroid and radius are the surface's, the same
  // values as formed here from the host's vertices.
  const bool deformed = !bs.force_slots.empty();
  for (std::size_t i = 0; i < sc.triangles.size(); ++i) {
    const int t = sc.triangles[i];
    const int parts = sc.parts[i] & (has_shaft ? 3 : 1);
    if (parts == 0) continue;
    // Per part: 1 its plane tests at this pose decide the edge and face search; with the
    // reusable list's verdict (search_verdicts) 2 search, 0 no search.
    const bool known = (sc.parts[i] & StepCandidates::kSearchKnown) != 0;
    const int nodes = known ? sc.nodes[i] : 63;
    // 3: search, the smooth tip's projection has no hit (Reusable::kNoProjection).
    auto search = [&](int part) {
      if (!known) return 1;
      if (!((sc.parts[i] >> (2 + part)) & 1)) return 0;
      return part == 0 && (sc.parts[i] >> 2) & StepCandidates::Reusable::kNoProjection ? 3 : 2;
    };
    const SurfaceTriangle& tri = tris[t];
    for (int g = g_first; g <= g_last; ++g) {
      std::array<Vec3, 3> moved;
      const std::array<Vec3, 3>* x = &b.surface.rest_vertices(t);
      Vec3 n, centre;
      double rho = 0.0;
      if (!triangle_geometry(m, body, t, g == 0 && deformed, moved, x, n, centre, rho)) continue;
      const std::array<Vec3, 3>* smooth =
          m.options_.contact_smooth_normals ? &b.surface.node_normals(t) : nullptr;
      for (int part = 0; part < 2; ++part)
        if (parts & (1 << part))
          part_features(t, tri, *x, n, centre, rho, part == 1, g == 1, shape, p0, p1, margin,
                        b.behind_reach_m, b.body->contact_normals(), bs, memo, smooth,
                        search(part), (nodes >> (3 * part)) & 7, lin);
    }
  }
  if (first_is_rest) {
    sc.rest_hits.assign(hits_.begin(), hits_.end());
    for (FeatureHit& h : sc.rest_hits) h.at_rest = true;
    sc.rest_hits_valid = true;
  }
}

// The hits of one tool part on one triangle (positions x, unit normal n): its vertices inside
// the part (+ margin; node_hits) and the triangle's closest point when it is an edge or face
// point (the smooth tip's projection along the interpolated normals, smooth_projection_hit, else
// edge_or_face_hit).
void State::part_features(int t, const SurfaceTriangle& tri, const std::array<Vec3, 3>& x,
                          const Vec3& n, const Vec3& centre, double rho, bool shaft,
                          bool at_rest, const ToolShape& shape,
                          const Vec3& p0, const Vec3& p1, double margin,
                          double max_penetration_m, const std::vector<Vec3>& node_normals,
                          BodyState& bs, long long memo, const std::array<Vec3, 3>* smooth_normals,
                          int search, int node_mask, const TierLinearization* lin) {
  const double reach = (shaft ? shape.shaft_radius_m : shape.tip_radius_m) + margin;
  FeatureHit h;
  h.triangle = t;
  h.shaft = shaft;
  h.at_rest = at_rest;
  h.face_normal = n;
  node_hits(tri, x, shape, p0, p1, reach, max_penetration_m, node_normals, bs, memo, node_mask,
            lin, h);
  // Most candidates are far from the part (the box reaches behind_reach behind the surface):
  // their face or edge point is skipped by a plane test before the closest-point search, and
  // that test by a sphere-capsule one (may_reach_triangle: the same rejections, cheaper). On the
  // reusable list the tests were made for the poses near this one (search: 0 none can hit, 2 it
  // may, 3 it may but not by the smooth tip's projection; search_verdicts), 1 here.
  if (search == 0) return;
  const double behind = std::max(reach, max_penetration_m);
  if (search == 1 &&
      (!may_reach_triangle(centre, rho + reach + behind, p0, shaft ? p1 : p0) ||
       !may_touch_face(x[0], n, centre, rho, p0, shaft ? p1 : p0, reach, behind) ||
       (shaft && beside_axis(x, n, p0, p1, reach))))
    return;
  if (!shaft && smooth_normals != nullptr) {
    if (search != 3 &&
        smooth_projection_hit(x, *smooth_normals, p0, reach, max_penetration_m, h))
      return;
    // No point of the triangle within reach has the centre on its interpolated normal (beside a
    // steep facet whose node normals turn far from its face normal: on the 4 and 5 mm brains the
    // tip 1 mm from a 2.9 mm step's top edge, the projection landing on none of the triangles
    // within reach, and the tip left with one radial node row, 0.2-0.5 of the force around). The
    // triangle's flat face or edge hit (the closest point, as without smooth normals) stands in;
    // the merge keeps such rows only where the tip has no projected face row on the body.
    h.flat_fallback = true;
  }
  edge_or_face_hit(tri, x, n, shape, p0, p1, reach, max_penetration_m, h);
}

// part_features: the triangle's vertices inside the part (each node's own closest centre; h: the
// hit's triangle, part, geometry and face normal). One hit per node, geometry and part: a node
// seen again from another of its triangles adds that triangle's normal to the hit's sum (the
// mean normal of the merge) and the hit keeps the lowest triangle (the merge's choice), so the
// merge sorts nodes, not node-triangle pairs. (node_mask: the vertices that can be hit,
// search_verdicts; the others are not tested.) Unit m.
void State::node_hits(const SurfaceTriangle& tri, const std::array<Vec3, 3>& x,
                      const ToolShape& shape, const Vec3& p0, const Vec3& p1, double reach,
                      double max_penetration_m, const std::vector<Vec3>& node_normals,
                      BodyState& bs, long long memo, int node_mask,
                      const TierLinearization* lin, FeatureHit& h) {
  const int t = h.triangle;
  const bool shaft = h.shaft;
  const Vec3 n = h.face_normal;
  for (int k = 0; k < 3; ++k) {
    if (tri.slot[k] < 0 || !(node_mask & (1 << k))) continue;
    const std::size_t i = 4 * static_cast<std::size_t>(tri.slot[k]) + (h.at_rest ? 2 : 0) + shaft;
    BodyState::NodeTest& test = bs.node_tests[i];
    if (test.stamp == memo) {
      if (!test.in) continue;
      FeatureHit& seen = hits_[static_cast<std::size_t>(test.hit)];
      seen.face_normal += n;
      ++seen.normals;
      if (t < seen.triangle) {
        seen.triangle = t;
        seen.at.weights = {0.0, 0.0, 0.0};
        seen.at.weights[k] = 1.0;
        seen.at.a = k;
      }
      continue;
    }
    const Vec3 ck = shaft ? closest_on_segment(x[k], p0, p1) : p0;
    test.stamp = memo;
    // The multirate tiers test the tip's node at rest and where their latest equilibrium carried
    // it (x + u*; carried_row_geometry): the nodes that ring a deep press's tip are then all
    // rows, not only those whose rest point was within reach. The rest point stays the row's.
    const Vec3& nk = node_normals[tri.slot[k]];
    test.in = within(ck - x[k], nk, reach, max_penetration_m) ||
              (lin && !shaft &&
               within(ck - x[k] - lin->displacement_m[static_cast<std::size_t>(tri.slot[k])], nk,
                      reach, max_penetration_m));
    test.in = test.in && !(shaft && inside_tip(x[k], p0, shape));
    if (!test.in) continue;
    test.hit = static_cast<int>(hits_.size());
    h.key = feature_key(shaft, TriangleFeature::kVertex, 0, tri.node[k]);
    h.at.point_m = x[k];
    h.at.weights = {0.0, 0.0, 0.0};
    h.at.weights[k] = 1.0;
    h.at.feature = TriangleFeature::kVertex;
    h.at.a = k;
    h.centre_m = ck;
    hits_.push_back(h);
  }
}

// part_features, SimulationOptions::contact_smooth_normals, the tip: the centre p0 projected
// along the normals interpolated from the nodes' (project_along_normals), one face row per
// triangle that holds the projection, its normal the interpolated one: no edge rows, and the row,
// its normal and its depth pass continuously from a triangle to the next across edges and
// creases. True (the hit added) if the projection lands within reach (unit m).
bool State::smooth_projection_hit(const std::array<Vec3, 3>& x,
                                  const std::array<Vec3, 3>& smooth_normals, const Vec3& p0,
                                  double reach, double max_penetration_m, FeatureHit& h) {
  TrianglePoint at;
  Vec3 smooth_n;
  double height = 0.0;
  if (!project_along_normals(p0, x, smooth_normals, at, smooth_n, height) ||
      !within(p0 - at.point_m, smooth_n, reach, max_penetration_m))
    return false;
  h.key = feature_key(false, TriangleFeature::kFace, 0, static_cast<std::uint64_t>(h.triangle));
  h.at = at;
  h.centre_m = p0;
  h.face_normal = smooth_n;
  hits_.push_back(h);
  return true;
}

// part_features: the triangle's closest point to the part's centre (the tip centre, or the shaft
// axis point closest to the triangle: shaft_centre) when it is an edge point within reach (by its
// distance only: behind a ridge the far flank's edge is not the surface the tool went through)
// or a face point within reach, also from behind (within). Unit m.
void State::edge_or_face_hit(const SurfaceTriangle& tri, const std::array<Vec3, 3>& x,
                             const Vec3& n, const ToolShape& shape, const Vec3& p0,
                             const Vec3& p1, double reach, double max_penetration_m,
                             FeatureHit& h) {
  TrianglePoint at;
  const Vec3 c = h.shaft ? shaft_centre(x, n, p0, p1, at, h.centre_slide) : p0;
  if (!h.shaft) at = closest_on_triangle(c, x);
  if (at.feature == TriangleFeature::kVertex) return;
  if (h.shaft && inside_tip(at.point_m, p0, shape)) return;
  if (at.feature == TriangleFeature::kEdge ? (c - at.point_m).norm() > reach
                                           : !within(c - at.point_m, n, reach, max_penetration_m))
    return;
  if (at.feature == TriangleFeature::kEdge) {
    const std::uint64_t a = tri.node[at.a], e = tri.node[(at.a + 1) % 3];
    h.key = feature_key(h.shaft, TriangleFeature::kEdge, std::min(a, e), std::max(a, e));
  } else {
    h.key = feature_key(h.shaft, TriangleFeature::kFace, 0, static_cast<std::uint64_t>(h.triangle));
  }
  h.at = at;
  h.centre_m = c;
  hits_.push_back(h);
}

// part_features, the shaft: its axis point (the segment p0-p1) closest to the triangle x (unit
// normal n) by alternating projections between the two convex sets, and `at` the triangle's
// closest point to it (unit m). Four rounds; once a round gives back its own centre bit for bit,
// the rounds left repeat it (the same inputs), so they are skipped: the same point as four rounds
// (a shaft beside a face parallel to it stops after the first).
// The centre's derivative in the tool's translation t, dc/dt = (I - u u^T) + u w^T (u the unit
// axis), carried through the rounds as w (centre_slide: FeatureHit::centre_slide; K's rows,
// merge_features): the rounds stop short of the closest pair where the axis is tilted against
// the triangle (each round leaves u . P u of the centre's distance to it, P the projection onto
// the feature reached: 1 - (n . u)^2 on a face, (e . u)^2 on an edge), so the centre and the
// point depend on t through the rounds made, not through the closest pair's formula.
Vec3 State::shaft_centre(const std::array<Vec3, 3>& x, const Vec3& n, const Vec3& p0,
                         const Vec3& p1, TrianglePoint& at, Vec3& centre_slide) {
  // (closest_on_segment's axis, its squared length and unit axis formed once per segment: the
  // same values for every triangle of the pose)
  AxisMemo& axis = shaft_axis_;
  if (!axis.valid || std::memcmp(axis.p0.data(), p0.data(), sizeof(Vec3)) != 0 ||
      std::memcmp(axis.p1.data(), p1.data(), sizeof(Vec3)) != 0) {
    axis.p0 = p0;
    axis.p1 = p1;
    axis.e = p1 - p0;
    axis.len2 = axis.e.squaredNorm();
    axis.u = axis.len2 > 0.0 ? Vec3(axis.e / std::sqrt(axis.len2)) : Vec3::Zero();
    axis.valid = true;
  }
  const Vec3 e = axis.e;
  const double len2 = axis.len2;
  const Vec3 u = axis.u;
  Vec3 w = Vec3::Zero();
  // The axis point of q (clamped to the segment: there dc/dt = I, w = u); dq/dt = P dc/dt with
  // P u = pu gives dnext/dt = (I - u u^T) + u ((I - u u^T) pu + (u . pu) w)^T inside it.
  auto on_axis = [&](const Vec3& q, const Vec3& pu) {
    if (len2 == 0.0) return p0;
    const double s = (q - p0).dot(e) / len2;
    if (!(s > 0.0 && s < 1.0)) {
      w = u;
      return Vec3(p0 + std::clamp(s, 0.0, 1.0) * e);
    }
    const double along = u.dot(pu);
    w = pu - along * u + along * w;
    return Vec3(p0 + s * e);
  };
  // P u of the point's feature: the face's plane, the edge's line, a vertex (fixed).
  auto projected_axis = [&](const TrianglePoint& q) -> Vec3 {
    if (q.feature == TriangleFeature::kFace) return u - n.dot(u) * n;
    if (q.feature == TriangleFeature::kVertex) return Vec3::Zero();
    const Vec3 d = (x[(q.a + 1) % 3] - x[q.a]).normalized();
    return d.dot(u) * d;
  };
  Vec3 c = on_axis((x[0] + x[1] + x[2]) / 3.0, Vec3::Zero());
  bool fixed = false;
  for (int it = 0; it < 4 && !fixed; ++it) {
    at = closest_on_triangle(c, x);
    // (A round that gives its own centre back leaves w as it was: on a vertex pu = 0 and w = 0
    // before and after, on a face parallel to the axis pu = u, at an end w = u.)
    const Vec3 next = on_axis(at.point_m, projected_axis(at));
    fixed = std::memcmp(next.data(), c.data(), sizeof(Vec3)) == 0;
    c = next;
  }
  centre_slide = w;
  if (!fixed) at = closest_on_triangle(c, x);
  return c;
}

// Phase "rows", helper of the merge: the distance of c to the closest point of the flat
// candidate triangles of (tool, body) that face the side of `facing` (n_t . facing > 0: not the
// far wall of a fold), on the rest surface or the deformed one, at most at_most_m (the caller's
// own triangle is within it: only triangles whose rest bounding sphere, widened by the surface's
// allowed displacement, comes nearer are tested). With `closest`: the closest point, where one
// nearer than at_most_m was found (else left as it was).
double State::flat_distance(const Model& m, int body, int tool, const Vec3& c, const Vec3& facing,
                            bool at_rest, double at_most_m, Vec3* closest) {
  const BodyModel& b = m.bodies_[body];
  const auto& tris = b.surface.triangles();
  const auto& rest = b.body->contact_mesh().vertices();
  const StepCandidates& sc = step_candidates_[tool * bodies_.size() + body];
  const double moved = at_rest ? 0.0 : sc.moved_m;
  double best2 = at_most_m * at_most_m;
  double best = std::sqrt(best2);
  for (int t : sc.triangles) {
    // |centroid - c| > radius + moved + best (norm_at_most: the norm's decision, its root only
    // near the bound).
    if (!norm_at_most((b.surface.centroid(t) - c).squaredNorm(), b.surface.radius_m(t) + moved + best))
      continue;
    const SurfaceTriangle& tri = tris[t];
    std::array<Vec3, 3> x;
    for (int k = 0; k < 3; ++k)
      x[k] = !at_rest && tri.slot[k] >= 0 ? position(m, body, tri.slot[k]) : rest[tri.node[k]];
    if (!((x[1] - x[0]).cross(x[2] - x[0]).dot(facing) > 0.0)) continue;
    const Vec3 q = closest_on_triangle(c, x).point_m;
    const double d2 = (c - q).squaredNorm();
    if (d2 < best2) {
      best2 = d2;
      best = std::sqrt(best2);
      if (closest) *closest = q;
    }
  }
  return std::sqrt(best2);
}

// Phase "rows", helper of the merge (the smooth tip): the tip's projection along the
// interpolated normals that lands on an edge or a vertex (a weight within project_along_normals'
// inclusion tolerance of 0) is held by every triangle there, each giving the same point, normal
// and depth: the copies are one row, kept from the lowest triangle (as the merge keeps a feature's
// lowest). Kept, the copies split one row's force between them: the cube's press centred on
// vertices of valence 4-8 gave the force and K of the pose 1e-9 m beside the vertex (one
// triangle holds it) to 7 digits with 5-9 rows instead of 2, and four_probes_bench
// --at-vertices 64.81 rows per step at 172-186 us.
void State::drop_shared_projections(double tip_radius_m) {
  constexpr double kOnBoundary = 1e-12;  // project_along_normals' inclusion tolerance
  const double same = 1e-9 * tip_radius_m;  // the copies differ by the projection's round-off
  auto on_boundary = [&](const FeatureHit& h) {
    if (h.triangle < 0 || h.shaft || h.flat_fallback ||
        key_feature(h.key) != TriangleFeature::kFace)
      return false;
    for (const double w : h.at.weights)
      if (w <= kOnBoundary) return true;
    return false;
  };
  // Each boundary hit against the earlier boundary hits only (boundary_hits_, ascending: the
  // pairs and their order of the test over all earlier hits, which skipped the others): linear
  // in the hits, quadratic in the boundary hits alone (the copies at an edge or vertex).
  bool dropped = false;
  boundary_hits_.clear();
  for (std::size_t i = 0; i < hits_.size(); ++i) {
    if (!on_boundary(hits_[i])) continue;
    for (const std::size_t j : boundary_hits_) {
      FeatureHit& a = hits_[i];
      FeatureHit& c = hits_[j];
      if (!on_boundary(c) || c.at_rest != a.at_rest ||
          (a.at.point_m - c.at.point_m).squaredNorm() > same * same)
        continue;
      (a.triangle < c.triangle ? c : a).triangle = -1;  // dropped
      dropped = true;
      if (a.triangle < 0) break;
    }
    boundary_hits_.push_back(i);
  }
  if (!dropped) return;
  std::size_t kept = 0;
  for (std::size_t i = 0; i < hits_.size(); ++i)
    if (hits_[i].triangle >= 0) hits_[kept++] = hits_[i];
  hits_.resize(kept);
}

// Phase "rows", merge: one row per feature (an edge only where all its triangles report it),
// normals, depths on the deformed and the rest surface. In named steps: the feature's hits
// (feature_hits), its triangle's nodes (feature_nodes), the row's normal and slides (a face:
// face_row_geometry; a node or edge: exit_row_geometry, LINEAR, carried_row_geometry, the
// tiers' tip, or radial_row_geometry, the tiers' shaft; LINEAR's tip edge: edge_slide), the row itself (feature_row), then the flat fallback rows
// (drop_fallback_rows) and the rows behind the surface (drop_behind_rows) left out.
void State::merge_features(const Model& m, int body, int tool, const ToolShape& shape,
                           const Vec3& tip, const Vec3& axis) {
  const BodyModel& b = m.bodies_[body];
  const auto& tris = b.surface.triangles();
  const std::size_t first = tool_rows_.size();
  tool_row_centre_.clear();  // per row from `first` on
  tool_row_plane_.clear();
  tool_row_plane_h_.clear();
  tool_row_fallback_.clear();
  bool projected_face = false;  // the tip has a projected face row on the body (smooth_tip)
  const bool smooth_tip = m.options_.contact_smooth_normals;
  if (smooth_tip) drop_shared_projections(shape.tip_radius_m);
  // One row per feature, from the deformed surface's hits when there are any (else the rest
  // surface's): sorted by feature, then geometry, then triangle (sort_hits).
  sort_hits();
  for (std::size_t i = 0; i < hits_.size();) {
    const std::size_t i0 = i;
    FeatureRow fr;
    i = feature_hits(i0, fr);
    const FeatureHit& h = hits_[i0];
    const SurfaceTriangle& tri = tris[h.triangle];
    const TriangleFeature f = key_feature(h.key);
    if (f == TriangleFeature::kEdge && fr.reports != tri.edge_triangles[h.at.a]) continue;
    fr.d = h.centre_m - h.at.point_m;
    fr.dn = fr.d.norm();
    fr.depth_centre = h.centre_m;
    if (f != TriangleFeature::kVertex) feature_nodes(m, body, h, fr);
    if (f == TriangleFeature::kFace) {
      face_row_geometry(b, h, axis, smooth_tip, fr);
    } else if (!tier_) {
      exit_row_geometry(shape, h, tip, axis, fr);
    } else if (h.shaft) {
      radial_row_geometry(shape, h, axis, fr);
    } else {
      carried_row_geometry(m, body, shape, h, fr);
    }
    if (f == TriangleFeature::kEdge && !h.shaft && !tier_) edge_slide(fr);
    // The turn as the haptic model can use it: the station extrapolates over the validity radius,
    // at least a quarter of the tip's radius (answer), so a normal turning faster than 1 rad per
    // quarter radius of the part (a radial row with the centre by the feature, |d| -> 0; an exit
    // row's line at its tangent to the sphere, where dn/dd grows as 1 / sqrt(r^2 - perp^2)) is
    // not linear over it: there the turn is scaled to that rate (the secant over the reach, not
    // the tangent). Unscaled, a press cycle on the stability suite's blocks sent |K| = 1.2e9 N/m.
    if (!fr.turn.isZero(0.0)) {
      const double most = 4.0 / (h.shaft ? shape.shaft_radius_m : shape.tip_radius_m);
      const double jn = fr.turn.norm();
      if (jn > most) fr.turn *= most / jn;
    }
    // A part whose centre lies deeper than behind_reach behind the surface does not push it.
    if ((fr.exit_row ? fr.plane_h : fr.n.dot(fr.d)) < -b.behind_reach_m) continue;
    // (made in place: a Row is ~1 kB, and most of the merge's time was copying them)
    Row& r = tool_rows_.emplace_back();
    if (!feature_row(m, body, tool, shape, h, fr, r)) {  // all on fixed nodes
      tool_rows_.pop_back();
      continue;
    }
    tool_row_centre_.push_back(h.centre_m);
    tool_row_plane_.push_back(fr.exit_row ? fr.plane_n : r.normal);
    tool_row_plane_h_.push_back(fr.exit_row ? fr.plane_h : r.height_m);
    tool_row_fallback_.push_back(h.flat_fallback ? 1 : 0);
    if (smooth_tip && f == TriangleFeature::kFace && !h.shaft && !h.flat_fallback) projected_face = true;
  }
  // The flat fallback rows only where no triangle holds the tip's projection.
  if (projected_face) drop_fallback_rows(first);
  drop_behind_rows(first, shape, axis);
}

// Phase "rows", merge (merge_features): the hits sorted by feature, then geometry (the deformed
// surface's first), then triangle. A total order (one hit per feature, geometry and triangle:
// a node's hits are one per geometry and part, a triangle gives one edge or face hit per part),
// so sorting 24-byte records of these (hit_order_) and moving each hit once gives the order of
// sorting the ~150-byte hits themselves.
void State::sort_hits() {
  hit_order_.clear();
  for (std::size_t i = 0; i < hits_.size(); ++i) {
    const FeatureHit& h = hits_[i];
    hit_order_.push_back({h.key,
                          (static_cast<std::uint64_t>(h.at_rest ? 1 : 0) << 32) |
                              static_cast<std::uint32_t>(h.triangle),
                          i});
  }
  std::sort(hit_order_.begin(), hit_order_.end(), [](const HitOrder& a, const HitOrder& c) {
    if (a.key != c.key) return a.key < c.key;
    return a.then < c.then;
  });
  sorted_hits_.clear();
  for (const HitOrder& o : hit_order_) sorted_hits_.push_back(hits_[o.index]);
  hits_.swap(sorted_hits_);
}

// Phase "rows", merge (merge_features): the hits of the feature of hits_[i0] (sorted: they
// follow it) on i0's geometry: their face normals summed (unit normals: fr.normals), how many
// report it; returns the index after the feature's hits.
std::size_t State::feature_hits(std::size_t i0, FeatureRow& fr) const {
  const FeatureHit& h = hits_[i0];
  std::size_t j = i0;
  for (; j < hits_.size() && hits_[j].key == h.key; ++j) {
    if (hits_[j].at_rest != h.at_rest) continue;
    fr.normal_sum += hits_[j].face_normal;
    ++fr.reports;
    fr.normals += hits_[j].normals;
  }
  return j;
}

// Phase "rows", merge: the hit's triangle's nodes, deformed where the hit was found, else at rest
// (unit m), and an edge hit's unit direction: formed once per row (the smooth face row's
// Jacobian, the edge's slide, the barycentric weights' gradient).
void State::feature_nodes(const Model& m, int body, const FeatureHit& h, FeatureRow& fr) {
  const SurfaceTriangle& tri = m.bodies_[body].surface.triangles()[h.triangle];
  const auto& rest = m.bodies_[body].body->contact_mesh().vertices();
  for (int k = 0; k < 3; ++k)
    fr.x[k] = !h.at_rest && tri.slot[k] >= 0 ? position(m, body, tri.slot[k]) : rest[tri.node[k]];
  if (key_feature(h.key) == TriangleFeature::kEdge)
    fr.edge = (fr.x[(h.at.a + 1) % 3] - fr.x[h.at.a]).normalized();
}

// Phase "rows", merge: a face row's normal (the triangle's, or the smooth tip's interpolated
// one) and, LINEAR, its slides: the shaft's depth (its centre slides along the axis), the smooth
// tip's projected point and turning normal (J^-1, below), the flat tip's projected point.
void State::face_row_geometry(const BodyModel& b, const FeatureHit& h, const Vec3& axis,
                              bool smooth_tip, FeatureRow& fr) {
  const Vec3& n = h.face_normal;
  fr.n = n;
  // A shaft face row's depth is its centre's height over the plane, the centre moving by
  // (I - u u^T) + u w^T (part_features): n^T G = n^T - (n . u)(u - w)^T.
  if (h.shaft && !tier_) {
    fr.depth_slide = n.dot(axis) * (h.centre_slide - axis);
    fr.point_slide = (Mat3::Identity() - n * n.transpose()) *
                     (Mat3::Identity() - axis * axis.transpose() +
                      axis * h.centre_slide.transpose());
  } else if (!tier_ && smooth_tip && !h.flat_fallback) {
    // The smooth tip's projected face row (part_features: project_along_normals): the centre
    // c = p0 + u e1 + v e2 + s N(u, v), N = nn0 + u (nn1 - nn0) + v (nn2 - nn0), so
    // d(u, v, s) = J^-1 dc with J = [e1 + s dN/du, e2 + s dN/dv, N]: the point slides by
    // [e1 e2 0] J^-1 and the normal N / |N| turns by (I - n n^T) / |N| [dN/du dN/dv 0] J^-1.
    // (The depth, the centre's distance to the flat surface: feature_row, with the lift.)
    const std::array<Vec3, 3>& nn = b.surface.node_normals(h.triangle);
    const std::array<Vec3, 3>& x = fr.x;
    const Vec3 e1 = x[1] - x[0], e2 = x[2] - x[0];
    fr.smooth_dn[0] = nn[1] - nn[0];
    fr.smooth_dn[1] = nn[2] - nn[0];
    const Vec3& n1 = fr.smooth_dn[0];
    const Vec3& n2 = fr.smooth_dn[1];
    fr.smooth_n = nn[0] + h.at.weights[1] * n1 + h.at.weights[2] * n2;
    const Vec3& big_n = fr.smooth_n;
    const double s_along = fr.d.dot(big_n) / big_n.squaredNorm();
    Mat3 jac;
    jac.col(0) = e1 + s_along * n1;
    jac.col(1) = e2 + s_along * n2;
    jac.col(2) = big_n;
    if (std::abs(jac.determinant()) > 1e-300) {
      const Mat3 ji = jac.inverse();
      fr.point_slide = e1 * ji.row(0) + e2 * ji.row(1);
      // (Node normals equal to round-off, a flat face's: no turn, and normal_turn's sums
      // for turning rows are not formed for it.)
      if (n1.squaredNorm() + n2.squaredNorm() > 1e-24)
        fr.turn = (Mat3::Identity() - n * n.transpose()) / big_n.norm() *
                  (n1 * ji.row(0) + n2 * ji.row(1));
      fr.smooth_inverse = ji;
      fr.smooth_scale = s_along;
      fr.smooth_row = true;
    }
  } else if (!tier_ && !h.shaft) {
    // The tip's flat face row: the point is the centre's projection on the plane.
    fr.point_slide = Mat3::Identity() - n * n.transpose();
  }
}

// Phase "rows", merge, LINEAR: a node or an edge row's normal, turn (unit 1/m) and slides.
// The tip: the sphere's normal where the point, pushed along its line (radial while the centre
// is within the feature's normal cone, else turning into the mean normal; tool_geometry.hpp
// exit_normal), leaves the sphere; the depth r - n . d, the sphere's tangent plane there. Over a
// flat surface the line is the mean normal whatever the centre's height, so nothing switches
// when the centre crosses the rest surface (d = r) and n does not turn as the tip moves along it:
// K = -N W^-1 N^T is the press's derivative. Radial up to 90 degrees and the mean normal past it
// (before) switched every node row of a flat face at once at d = r: |F| of the 2 mm tip on 1 mm
// cells 7.87 -> 16.03 mN (linear-tet) and 3.36 -> 13.19 mN (smoothed-tet) over 0.02 mm at a
// vertex, and a radial row under the tip pushed it off its node sideways (d / |d| turns by
// dx / |d|: +62 kN/m across the 3 mm tip 2.9 mm into the cube's node, which K leaves out). A
// 60-90 degree blend of the radial direction into the mean normal made the press continuous but
// its normal turned with the tip's position far faster still (across the blend: the force's
// derivative 26 kN/m against K's 2.4) and the closed haptic loop against the cube oscillated for
// good (bench/RESULTS.md, "The 60-90 degree blend withdrawn").
// The shaft: the same line against the capsule's cross-section through the point (the sphere of
// its radius about the axis point closest to the point; tool_geometry.hpp capsule_exit), the
// depth that sphere's tangent plane's where the point leaves it. Radial up to 90 degrees and the
// mean normal past it (before) switched the row's direction by up to 90 degrees where the axis
// crossed the feature's tangent plane: a shaft tilted 6 degrees, swept into a face of 1 mm cells
// in 5 um steps, had a step 4.83 times the median (the force falling 6.05 -> 5.70 mN), and a
// shaft lying in the face 0.45 mm deep was pushed sideways by 15 % of |F| (bench/RESULTS.md,
// "The shaft's exit point").
void State::exit_row_geometry(const ToolShape& shape, const FeatureHit& h, const Vec3& tip,
                              const Vec3& axis, FeatureRow& fr) {
  const Vec3 mean = fr.normal_sum.normalized();
  const double cos_alpha = fr.normal_sum.norm() / std::max(fr.normals, 1);
  const Vec3& d = fr.d;
  fr.exit_row = true;
  fr.plane_n = mean;
  fr.plane_h = d.dot(mean);
  const double part_r = h.shaft ? shape.shaft_radius_m : shape.tip_radius_m;
  fr.radial = fr.dn > 1e-9 * part_r && fr.plane_h > 0.0;  // not an entry (drop_behind_rows)
  fr.cos_alpha = cos_alpha;
  if (!h.shaft) {
    fr.n = exit_normal(d, mean, cos_alpha, shape.tip_radius_m);
    fr.turn = exit_normal_turn(d, mean, cos_alpha, shape.tip_radius_m);
    return;
  }
  Mat3 dn_dx;
  const CapsuleExit ex = capsule_exit(h.at.point_m, tip, tip + shape.shaft_length_m * axis, mean,
                                      cos_alpha, shape.shaft_radius_m, &dn_dx);
  const Vec3 n = ex.normal;
  fr.n = n;
  fr.depth_centre = ex.centre;
  // The tool's translation t moves the point relative to the capsule by (dx/dt - I) t: a node
  // stays (dx/dt = 0); an edge's point is the edge's point closest to the hit's centre, which
  // part_features' rounds found (d centre / dt = (I - u u^T) + u w^T, w the hit's
  // centre_slide), so dx/dt = e e^T ((I - u u^T) + u w^T). The rounds stop short of the two
  // lines' common normal where the edge runs near the axis ((e . u)^2 per round: 0.88 for the
  // fine block's z edges under the 20-degree shaft), so the common normal's slide
  // (t . e - b t . u) / (1 - b^2), b = e . u (before), was not the point's (bench/RESULTS.md,
  // "The tilted shaft's K against central differences").
  Mat3 slide = Mat3::Zero();
  if (key_feature(h.key) == TriangleFeature::kEdge) {
    const Vec3& e = fr.edge;
    const double eu = e.dot(axis);
    slide = e * (e - eu * axis + eu * h.centre_slide).transpose();
  }
  fr.turn = dn_dx * (slide - Mat3::Identity());
  // The depth r - n . (centre - point) changes by -n^T G t with the normal held, G =
  // d (centre - point) / dt = (I - u u^T)(I - dx/dt) where the point's axis point is inside the
  // segment (the centre slides along the axis), I - dx/dt at an end; K's -N W^-1 N^T takes G = I
  // (the tip's rows), normal_turn adds the difference.
  const double s_c = (h.at.point_m - tip).dot(axis);
  Vec3 g = n - slide.transpose() * n;
  if (s_c > 0.0 && s_c < shape.shaft_length_m) g -= axis * axis.dot(g);
  fr.depth_slide = g - n;
  fr.point_slide = slide;
}

// Phase "rows", merge, the multirate tiers: a node or an edge row radial from the part's centre
// (the point against a rigid sphere or capsule) when the centre is within 60 degrees of the mean
// normal of the triangles that report it, else along that mean normal (the depth r - n . d), and
// its turn (unit 1/m): the shaft's rows (the tip's: carried_row_geometry). 60, not 90: the depth adds n . u0 of an equilibrium that may have carried the point far along the
// surface, which a nearly tangential normal turns into a depth (measured with 90: a 10 mm vertex
// press cycle in NONLINEAR reached 101.6 N against the block's 50.5 N bound, stability_test).
void State::radial_row_geometry(const ToolShape& shape, const FeatureHit& h, const Vec3& axis,
                                FeatureRow& fr) {
  const Vec3 mean = fr.normal_sum.normalized();
  fr.cos_alpha = fr.normal_sum.norm() / std::max(fr.normals, 1);
  const Vec3& d = fr.d;
  const double dn = fr.dn;
  fr.radial = dn > 1e-9 * (h.shaft ? shape.shaft_radius_m : shape.tip_radius_m) &&
              d.dot(mean) > 0.5 * dn;  // cos 60 degrees
  fr.n = fr.radial ? Vec3(d / dn) : mean;
  // A radial row's normal d / |d| turns by (I - n n^T) / |d| per unit change of d. The shaft's
  // centre is the axis point nearest the feature: against a node it slides along the axis (d
  // changes by the move across the axis, where the point is inside the segment); against an
  // edge the common normal of the two lines keeps its direction (no turn while they are not
  // parallel).
  if (fr.radial) {
    fr.turn = (Mat3::Identity() - fr.n * fr.n.transpose()) / dn;
    if (h.shaft) {
      if (key_feature(h.key) == TriangleFeature::kEdge) {
        fr.turn.setZero();
      } else if (std::abs(d.dot(axis)) < 1e-9 * dn) {
        fr.turn = fr.turn * (Mat3::Identity() - axis * axis.transpose());
      }
    }
  }
}

// Phase "rows", merge: the tip's edge row. LINEAR: its point (the edge point closest to the
// centre) slides along the edge by e e^T (Row::point_slide) while the centre is inside the edge's
// wedge of normals. Between coplanar triangles the wedge is their plane: the centre leaves it as
// the tool moves across, and the point goes on into a triangle's face, so it slides by I - n n^T
// and the normal (the plane's) does not turn; the triangle it enters depends on the side, so the
// barycentric weights have a kink there (no weight_slide: held) and only a spread's weights
// (smooth in the point) follow it. The edge's closest point slides along the edge as the tool
// moves, so d changes by the move across it (the turn). (The tiers' tip edges:
// carried_row_geometry; the shaft's edge rows have no slide.)
void State::edge_slide(FeatureRow& fr) const {
  const Vec3& e = fr.edge;
  if (fr.cos_alpha > 1.0 - 1e-12) {
    const Vec3 mean = fr.normal_sum.normalized();
    fr.point_slide = Mat3::Identity() - mean * mean.transpose();
    fr.turn.setZero();  // the face row it becomes has the plane's normal
    fr.weights_kink = true;
  } else {
    fr.point_slide = e * e.transpose();
  }
  if (!fr.turn.isZero(0.0)) fr.turn = fr.turn * (Mat3::Identity() - e * e.transpose());
}

// Phase "rows", merge, the multirate tiers: the tip's node or edge row as LINEAR's exit row
// (exit_row_geometry) from the point as the tier's latest equilibrium carried it along the mean
// normal m of the triangles that report it, x = p + m (m . u), u = sum_k w_k u*_k
// (TierLinearization::displacement_m), its line m; its turn (unit 1/m; an edge's carried point
// slides by the carried edge per unit of the rest point's slide). The depth is the rest one,
// r - n . (c - p) + n . u0 (feature_row; u0 = u* - R C R^T f*), to which the LCP adds
// n . R C R^T f, plus n . (c - y) - |c - y|, y = p + u the point as the equilibrium carried it
// (FeatureRow::depth_add): at the tier's fixed point (f = f*) r - |c - y|, the sphere against
// that point. Rows and planes stay the rest
// surface's, so the step and the updates remain a fixed-point iteration, and the rows are a
// function of the latest equilibrium alone (no share, no history): one fixed point. The tangential
// part of u* is left out of the line: a node loaded alone, carried sideways under the tip, took
// the exit normal of a point off the centre's axis, which pushes it further (lateral stiffness
// -F / |c - x|), and slid off the tip (the exposed cylinder's 10 mm cycle; bench/RESULTS.md, "The
// tiers' rows as a function of the equilibrium alone"). The 60-degree rows before pressed a node
// under the tip's centre as a flat punch: a vertex twice as hard as an edge or a face (the
// block's 10 mm press cycles: 1.025 / 0.508 / 0.508 N in NONLINEAR against LINEAR's 0.503 /
// 0.488 / 0.460; these rows 0.505 / 0.488 / 0.460). The shaft keeps the 60-degree rows
// (radial_row_geometry).
void State::carried_row_geometry(const Model& m, int body, const ToolShape& shape,
                                 const FeatureHit& h, FeatureRow& fr) const {
  const Vec3 mean = fr.normal_sum.normalized();
  fr.cos_alpha = fr.normal_sum.norm() / std::max(fr.normals, 1);
  fr.exit_row = true;
  fr.plane_n = mean;
  fr.plane_h = fr.d.dot(mean);
  fr.radial = fr.dn > 1e-9 * shape.tip_radius_m && fr.plane_h > 0.0;  // not an entry
  const SurfaceTriangle& tri = m.bodies_[body].surface.triangles()[h.triangle];
  const TierLinearization& lin = tier_->linearization(body);
  const bool carried = !lin.displacement_m.empty();
  auto u_at = [&](int k) {
    return carried && tri.slot[k] >= 0 ? lin.displacement_m[static_cast<std::size_t>(tri.slot[k])]
                                       : Vec3(Vec3::Zero());
  };
  Vec3 u = Vec3::Zero();
  for (int k = 0; k < 3; ++k)
    if (h.at.weights[k] != 0.0) u += h.at.weights[k] * u_at(k);
  const Vec3 x = h.at.point_m + mean * mean.dot(u);
  const Vec3 d = h.centre_m - x;
  const double r = shape.tip_radius_m;
  fr.n = exit_normal(d, mean, fr.cos_alpha, r);
  fr.turn = exit_normal_turn(d, mean, fr.cos_alpha, r);
  const Vec3 to_carried = h.centre_m - h.at.point_m - u;  // c - (p + u)
  fr.depth_add = fr.n.dot(to_carried) - to_carried.norm();
  if (key_feature(h.key) == TriangleFeature::kEdge && !fr.turn.isZero(0.0)) {
    const auto& rest = m.bodies_[body].body->contact_mesh().vertices();
    const int k0 = h.at.a, k1 = (h.at.a + 1) % 3;
    const double length = (rest[tri.node[k1]] - rest[tri.node[k0]]).norm();
    const Vec3 moved = fr.edge + mean * (mean.dot(u_at(k1) - u_at(k0)) / length);
    fr.turn = fr.turn * (Mat3::Identity() - moved * fr.edge.transpose());
  }
}

// Phase "rows", merge: the row of a feature from its first hit and its geometry (fr): the
// weights' gradient (row_weight_slide), its triangle's nodes by the point's barycentric weights
// or the spread pending (row_spread_inputs), its height, depth and rest depth (unit m; the smooth
// tip's projected face row measured to the flat surface: smooth_lift). False if the row rests on
// fixed nodes only.
bool State::feature_row(const Model& m, int body, int tool, const ToolShape& shape,
                        const FeatureHit& h, const FeatureRow& fr, Row& r) {
  const BodyModel& b = m.bodies_[body];
  const SurfaceTriangle& tri = b.surface.triangles()[h.triangle];
  const auto& rest = b.body->contact_mesh().vertices();
  const TierLinearization* lin = tier_ ? &tier_->linearization(body) : nullptr;
  const TriangleFeature f = key_feature(h.key);
  const Vec3& n = fr.n;
  const double radius = h.shaft ? shape.shaft_radius_m : shape.tip_radius_m;
  r.body = body;
  r.tool = tool;
  r.shaft = h.shaft;
  r.key = h.key;
  r.normal = n;
  r.turn = fr.turn;
  r.turn_depth = fr.turn.transpose() * (fr.depth_centre - h.at.point_m);
  r.depth_slide = fr.depth_slide;
  r.point_slide = fr.point_slide;
  if (!fr.point_slide.isZero(0.0) && !fr.weights_kink) row_weight_slide(fr, r);
  r.radial = fr.radial;
  r.point_m = h.at.point_m;
  // The row's nodes: its triangle's, by the point's barycentric weights, or the load spread
  // around the point (SimulationOptions::contact_spread). The gap is the point's either way.
  Vec3 rest_point = Vec3::Zero();
  r.nodes = 3;
  for (int k = 0; k < 3; ++k) {
    rest_point += h.at.weights[k] * rest[tri.node[k]];
    r.slot[k] = tri.slot[k];
    r.w[k] = h.at.weights[k];
  }
  if (m.options_.contact_spread > 0.0) row_spread_inputs(m, b, shape, h, fr, rest_point, r);
  Vec3 offset = Vec3::Zero();
  if (!r.spread_pending && !row_node_normals(r, lin, offset)) return false;
  r.height_m = n.dot(fr.depth_centre - h.at.point_m);
  double lift = 0.0;  // along-normal height less the flat one, unit m
  if (m.options_.contact_smooth_normals && f == TriangleFeature::kFace && !h.shaft &&
      !h.flat_fallback)
    lift = smooth_lift(m, body, tool, h, fr, r);
  r.depth_m = radius - r.height_m;
  // LINEAR: the LCP's W lambda is the whole displacement, so its depth is the rest one; the
  // other tiers add the offset u0 of the latest equilibrium (tier_equilibrium.hpp).
  r.rest_depth_m = radius - n.dot(fr.depth_centre - rest_point) + lift + fr.depth_add;
  if (!r.spread_pending) r.rest_depth_m += n.dot(offset);
  return true;
}

// Phase "rows", merge: the triangle's barycentric weights' gradient along the point's slide
// (Row::weight_slide, unit 1/m; in the triangle's plane: a face row's point stays in it, an edge
// row's on the edge, where the third weight's gradient is across it): grad w1 = e2 x f / |f|^2,
// grad w2 = f x e1 / |f|^2, f = e1 x e2, of the nodes fr.x.
void State::row_weight_slide(const FeatureRow& fr, Row& r) {
  const std::array<Vec3, 3>& x = fr.x;
  const Vec3 e1 = x[1] - x[0], e2 = x[2] - x[0], flat = e1.cross(e2);
  const double area2 = flat.squaredNorm();
  if (!(area2 > 0.0)) return;
  const Vec3 g1 = e2.cross(flat) / area2, g2 = flat.cross(e1) / area2;
  r.weight_slide.col(1) = r.point_slide.transpose() * g1;
  r.weight_slide.col(2) = r.point_slide.transpose() * g2;
  r.weight_slide.col(0) = -(r.weight_slide.col(1) + r.weight_slide.col(2));
}

// Phase "rows", merge (SimulationOptions::contact_spread): the spread's inputs (radius, the point
// at rest, the surface normal; unit m), the row spread once the step keeps it (spread_row; 43 %
// of the rows merged are dropped later: behind the surface, beyond the margin, the same
// constraint). The spread fades where the cells resolve the tool part (radius R): full for a
// local edge of R and more, none (the triangle's own barycentric rows) at R / 2 and less, linear
// in between. A spread over cells finer than the part smears a load the rows already sample and
// stiffens the press (the 2 mm tip 1 mm into 0.5 mm cells: 8.06 mN with it, 7.20 without,
// Sneddon 6.74). The tip's rows (LINEAR's and the tiers' alike, so that at vanishing load the
// tiers' rows are LINEAR's) spread over at least tip_spread_floor_m. Fixed per mesh and part, so
// the force stays continuous in time.
void State::row_spread_inputs(const Model& m, const BodyModel& b, const ToolShape& shape,
                              const FeatureHit& h, const FeatureRow& fr, const Vec3& rest_point,
                              Row& r) {
  const Vec3 surface_n =
      key_feature(h.key) == TriangleFeature::kFace ? h.face_normal : fr.normal_sum.normalized();
  const double edge = b.surface.edge_at_m(h.triangle, h.at.weights);
  const double part_r = h.shaft ? shape.shaft_radius_m : shape.tip_radius_m;
  const double fade = std::clamp((edge - 0.5 * part_r) / (0.5 * part_r), 0.0, 1.0);
  double rho = m.options_.contact_spread * edge * fade;
  if (!h.shaft) rho = std::max(rho, tip_spread_floor_m(edge, part_r));
  if (rho > 0.0) {
    r.spread_pending = true;
    r.spread_radius_m = rho;
    r.spread_at_m = rest_point;
    r.spread_normal = surface_n;
  }
}

// Phase "rows", merge (SimulationOptions::contact_smooth_normals, a tip face row): the point and
// the normal are the projection's along the interpolated normals, the height the centre's
// distance to the closest point of the flat surface (signed as the projection's height). Along a
// tilted normal the height above a flat triangle is longer than the distance (h / cos of the
// tilt): over a convex ridge of the 7 mm brain a tip 1 mm below the flat triangles was 0.6 mm
// below along the normal, and the near field's F ~ d^1.5 cut its force to a third. The distance
// to the flat surface is continuous as the centre moves (the minimum over the triangles of
// continuous distances), as the projection's point and normal are. r.height_m lowered by the lift
// (the along-normal height less the flat one, unit m, returned); LINEAR, r.depth_slide.
double State::smooth_lift(const Model& m, int body, int tool, const FeatureHit& h,
                          const FeatureRow& fr, Row& r) {
  const Vec3& n = fr.n;
  const double along = r.height_m;
  Vec3 q = Vec3::Constant(std::numeric_limits<double>::quiet_NaN());
  const double flat = flat_distance(m, body, tool, h.centre_m, n, h.at_rest, std::abs(along), &q);
  const double lift = along - std::copysign(flat, along);
  r.height_m -= lift;
  // LINEAR: the depth r - height follows -g . x, g the height's gradient: the direction from
  // the flat surface's closest point q, or where no triangle came nearer than the height
  // along N (the flat one), that height's: d(s |N|) = |N| ds + s n^T dN. depth_slide is g
  // less what the answer takes already (n and the turn's J^T d: normal_turn).
  if (fr.smooth_row) {
    Vec3 g;
    const Vec3 cq = h.centre_m - q;
    if (q.allFinite() && cq.norm() > 0.0) {
      g = std::copysign(1.0, along) * cq / cq.norm();
    } else {
      const Mat3& ji = fr.smooth_inverse;
      g = fr.smooth_n.norm() * ji.row(2).transpose() +
          fr.smooth_scale * (n.dot(fr.smooth_dn[0]) * ji.row(0).transpose() +
                             n.dot(fr.smooth_dn[1]) * ji.row(1).transpose());
    }
    r.depth_slide = g - n - r.turn_depth;
  }
  return lift;
}

// Phase "rows", merge: the tool's rows on the body (from `first` on) without its flat fallback
// rows (the smooth tip has a projected face row on the body).
void State::drop_fallback_rows(std::size_t first) {
  std::size_t kept = first;
  for (std::size_t k = first; k < tool_rows_.size(); ++k) {
    if (tool_row_fallback_[k - first]) continue;
    if (kept != k) {
      tool_rows_[kept] = tool_rows_[k];
      tool_row_centre_[kept - first] = tool_row_centre_[k - first];
      tool_row_plane_[kept - first] = tool_row_plane_[k - first];
      tool_row_plane_h_[kept - first] = tool_row_plane_h_[k - first];
    }
    ++kept;
  }
  tool_rows_.resize(kept);
  tool_row_centre_.resize(kept - first);
  tool_row_plane_.resize(kept - first);
  tool_row_plane_h_.resize(kept - first);
}

// Phase "rows", merge: the tool pushes the surface it entered; a row behind the surface (the
// part's centre behind its feature's plane) is kept only if the part can have reached its tissue
// through that surface. The entry is the row the centre is least deep under. A behind-row is
// dropped (a) when its normal turns more than 60 degrees from the entry's: another side of the
// body (a ridge's far flank, the far face of a thin part); or
// (b) when the part does not hold its feature point (the point farther than the part's radius
// r from the part's centre) and the point lies outside the layer the part has swept from the
// entry surface to where it is: more than r in front of the entry's plane (the part crossed
// that plane spanning r either side of it, and went on behind it) or more than r below the
// part's centre along the entry's normal (deeper than any point of the part). Such a point is
// on a surface the part never went through: the tissue behind it is not what the tool pushes.
// Seen on the 4 mm brain's slide at 2 mm deep (y 85.4 mm): a shaft face row on the far flank
// of the gyrus beside the tip, its normal 44 degrees from the entry's (a shaft row 0.05 mm in
// front of the near wall), the tip centre 5.24 mm behind its plane (6.74 mm deep), its point
// 3.0 mm in front of the entry's plane: 62.4 of the step's 69.7 mN. A row the part holds
// (|p - c| <= r) is a real intersection whatever its side, and a tool pushed deep through the
// surface keeps the rows of the surface it entered (their points lie in the layer: behind the
// entry's plane, not below the part).
// The entry is chosen among the rows the part touches (depth >= 0): a feature the part is clear
// of (in front by more than its radius) says nothing about where it entered. A centre on the
// surface (the height zero up to round-off, kOnSurfaceM) is not behind it. Seen on a 5 mm brain:
// the tip centre exactly on a crease edge (heights -1e-18 m), a far flank's untouched row the
// highest, and every row under the tool dropped: 0 N at 2 mm deep.
// A radial row (a node or edge against the part's sphere, the centre in front of it) is never
// behind the surface and its normal is the sphere's, not a side of the body: not an entry.
// (Seen with a curved contact surface: a face row 0.1 mm behind it at a 2 mm press, a node row
// beside the tip with a radial normal 70 degrees from it the highest, and the face row
// dropped: 0.4 mN.)
// The entry faces the tool's shaft side where any touched row does: a probe goes into tissue
// tip first, so the surface it went through faces back along its axis (plane normal . axis >
// 0). A touched row facing away is the underside of a lip beside the tip (a fold over a
// sulcus, which a brain meshed finely under the press resolves): the centre is far in front of
// it, so it was the entry, and every row of the surface pressed (its normal more than 60
// degrees from the lip's, the centre just behind it) was dropped: the 2 mm tip pressed 2.05 mm
// into the 7 mm brain refined to 0.5 mm cells under it kept 37 of 87 rows, 2.9 mN where 1.8 mm
// gave 9.6 mN.
void State::drop_behind_rows(std::size_t first, const ToolShape& shape, const Vec3& axis) {
  constexpr double kOnSurfaceM = 1e-12;
  if (tool_rows_.size() <= first) return;
  std::size_t entry = tool_rows_.size();
  for (int facing = 1; facing >= 0 && entry == tool_rows_.size(); --facing)
    for (std::size_t k = first; k < tool_rows_.size(); ++k) {
      if (tool_rows_[k].depth_m < 0.0 || tool_rows_[k].radial) continue;
      if (facing && !(tool_row_plane_[k - first].dot(axis) > 0.0)) continue;
      if (entry == tool_rows_.size() ||
          tool_row_plane_h_[k - first] > tool_row_plane_h_[entry - first])
        entry = k;
    }
  if (entry == tool_rows_.size()) return;  // nothing touched: no row is behind a surface
  const Vec3 n_entry = tool_row_plane_[entry - first];
  const Vec3 p_entry = tool_rows_[entry].point_m;
  std::size_t kept = first;
  for (std::size_t k = first; k < tool_rows_.size(); ++k) {
    const Row& r = tool_rows_[k];
    bool drop = false;
    if (tool_row_plane_h_[k - first] < -kOnSurfaceM) {
      const Vec3& c = tool_row_centre_[k - first];
      const double part_r = r.shaft ? shape.shaft_radius_m : shape.tip_radius_m;
      const double front = n_entry.dot(r.point_m - p_entry);  // in front of the entry's plane
      const double below = n_entry.dot(c - r.point_m);        // below the part's centre
      const bool held = (r.point_m - c).squaredNorm() <= part_r * part_r;
      const bool swept = front <= part_r && below <= part_r;
      drop = tool_row_plane_[k - first].dot(n_entry) < 0.5 || (!held && !swept);
    }
    if (drop) continue;
    if (kept != k) tool_rows_[kept] = r;
    ++kept;
  }
  tool_rows_.resize(kept);
}

// Phase "rows" of one tool: per body the candidates, their features, merged; then the deepest
// rows of the tool (at most max_contact_nodes_per_tool), appended to the step's rows.
void State::rows_of_tool(const Model& m, int tool, const ToolPose& pose, const Vec3& axis) {
  // The rest surface and the pose of the last search on it (bit for bit): its kept rows.
  ToolRowsMemo& memo = tool_rows_memo_[tool];
  if (rest_geometry_ && memo.valid && memo.tool == pose.tool &&
      std::memcmp(memo.tip_m.data(), pose.tip_m.data(), sizeof(double) * 3) == 0 &&
      std::memcmp(memo.axis.data(), pose.axis.data(), sizeof(double) * 3) == 0) {
    for (const Row& r : memo.rows) merge_tool_row(r);
    for (const SpreadMemo& e : memo.spreads)
      add_spread(e);
    geometry_rows_dropped_ += memo.dropped;
    return;
  }
  memo.valid = false;
  memo.rows.clear();
  memo.spreads.clear();
  memo.dropped = 0;
  const ToolShape& shape = m.tools_[pose.tool];
  const double margin = m.options_.candidate_margin * shape.tip_radius_m;
  tool_rows_.clear();
  for (int bi = 0; bi < static_cast<int>(m.bodies_.size()); ++bi) {
    if (m.bodies_[bi].surface.triangles().empty()) continue;
    candidate_triangles(m, bi, tool, pose, axis);
    triangle_features(m, bi, tool, pose, axis);
    merge_features(m, bi, tool, shape, pose.tip_m, axis);
  }
  // Rows within the margin enter the LCP inactive (caught if the deformation pushes them in).
  // The deepest first, sorted by index (a Row holds kSpreadNodes nodes: moving the rows through
  // the heap cost more than finding them); `deeper` is a total order on one tool's rows, so the
  // kept rows and their order are those of sorting the rows themselves.
  tool_order_.clear();
  for (std::size_t k = 0; k < tool_rows_.size(); ++k)
    if (tool_rows_[k].depth_m > -margin) tool_order_.push_back(static_cast<int>(k));
  // The kept rows are spread here (spread_row), deepest first, until the limit: a row whose
  // spread lands on fixed nodes only is left out and the next one taken.
  const std::size_t limit = static_cast<std::size_t>(m.options_.max_contact_nodes_per_tool);
  std::sort(tool_order_.begin(), tool_order_.end(),
            [&](int a, int b) { return deeper(tool_rows_[a], tool_rows_[b]); });
  // The kept rows' indices move to the front of tool_order_ (in their order).
  std::size_t kept = 0, k = 0;
  for (; k < tool_order_.size() && kept < limit; ++k) {
    Row& r = tool_rows_[tool_order_[k]];
    last_spread_ = nullptr;
    if (!spread_row(m, r)) continue;
    r.kept = true;
    tool_order_[kept++] = tool_order_[k];
    if (rest_geometry_ && last_spread_) copy_spread(memo.spreads.emplace_back(), *last_spread_);
  }
  // Touching rows past the limit are left out: counted (StepStats::contact_rows_dropped), never
  // silently. Rows within the margin only (inactive candidates) are not.
  int dropped = 0;
  for (; k < tool_order_.size(); ++k)
    if (tool_rows_[tool_order_[k]].depth_m > 0.0) ++dropped;
  // The near fields at the deepest kept rows, with the spread radius their spread ended with (a
  // spread that found no triangle leaves the row on its triangle's nodes, rho 0: no near field).
  near_field_of_tool(m, shape);
  near_field_of_shaft(m, shape, axis);
  for (std::size_t i = 0; i < kept; ++i) {
    const Row& r = tool_rows_[tool_order_[i]];
    if (rest_geometry_) memo.rows.push_back(r);  // (reserved: the limit)
    merge_tool_row(r);
  }
  geometry_rows_dropped_ += dropped;
  if (rest_geometry_) {
    memo.dropped = dropped;
    memo.valid = true;
    memo.tool = pose.tool;
    memo.tip_m = pose.tip_m;
    memo.axis = pose.axis;
  }
}

// Two tools on one feature, or on nearly the same constraint (the same main node, normals within
// 30 degrees): one row (the same constraint twice would leave only the row compliance between
// the tools, a stiffness of 1/eps); the deeper tool carries it. A tool's kept row, deepest first.
void State::merge_tool_row(const Row& r) {
  auto main_slot = [](const Row& q) {
    int best = 0;
    for (int k = 1; k < q.nodes; ++k)
      if (q.w[k] > q.w[best]) best = k;
    return q.slot[best];
  };
  // row_main_slot_: the merged rows' main slots, each formed once, kept beside rows_ (both
  // cleared by solve_geometry, the only caller's caller; rows_ grows only here while rows merge).
  const int main_r = main_slot(r);
  std::size_t same = 0;
  for (; same < rows_.size(); ++same) {
    const Row& o = rows_[same];
    if (o.body == r.body && o.tool != r.tool &&
        (o.key == r.key ||
         (main_r >= 0 && row_main_slot_[same] == main_r && o.normal.dot(r.normal) > 0.866)))
      break;
  }
  if (same == rows_.size()) {
    rows_.push_back(r);
    row_main_slot_.push_back(main_r);
  } else if (r.depth_m > rows_[same].depth_m) {
    rows_[same] = r;
    row_main_slot_[same] = main_r;
  }
}

// A spread memo entry with the row's inputs (bit for bit): this geometry's, else the last's
// (*from_last then true). The entries' keys are scanned (spread_keys_: 8 bytes an entry, where
// an entry is ~0.7 kB) and an entry compared only where its key is the row's.
const State::SpreadMemo* State::find_spread(const Row& r, bool* from_last) const {
  const std::uint64_t key = spread_key(r.body, r.spread_at_m, r.spread_normal, r.spread_radius_m);
  for (int l = 0; l < 2; ++l) {
    const std::vector<SpreadMemo>& list = l == 0 ? spread_memo_ : spread_prev_memo_;
    const std::vector<std::uint64_t>& keys = l == 0 ? spread_keys_ : spread_prev_keys_;
    for (std::size_t i = 0; i < keys.size(); ++i) {
      if (keys[i] != key) continue;
      const SpreadMemo& e = list[i];
      if (e.body == r.body && e.radius_m == r.spread_radius_m &&
          std::memcmp(e.at_m.data(), r.spread_at_m.data(), sizeof(double) * 3) == 0 &&
          std::memcmp(e.normal.data(), r.spread_normal.data(), sizeof(double) * 3) == 0 &&
          std::signbit(e.radius_m) == std::signbit(r.spread_radius_m)) {
        if (from_last) *from_last = l == 1;
        return &e;
      }
    }
  }
  return nullptr;
}

// A spread memo entry appended to this geometry's (within the reserved capacity), with its key.
void State::add_spread(const SpreadMemo& e) {
  if (spread_memo_.size() >= spread_memo_.capacity()) return;
  copy_spread(spread_memo_.emplace_back(), e);
  spread_keys_.push_back(spread_key(e.body, e.at_m, e.normal, e.radius_m));
}

// A spread memo entry copied into d without what is never read: the load's entries beyond its
// nodes, the gradient's beyond them and all of it without has_gradient (spread_row and
// slide_weights read k < nodes, the gradient only with has_gradient): ~0.2 of the entry's
// ~0.7 kB for a load of 8 nodes.
void State::copy_spread(SpreadMemo& d, const SpreadMemo& e) {
  d.body = e.body;
  d.at_m = e.at_m;
  d.normal = e.normal;
  d.radius_m = e.radius_m;
  d.found = e.found;
  d.load.nodes = e.load.nodes;
  d.load.dropped = e.load.dropped;
  const int n = std::clamp(e.load.nodes, 0, kSpreadNodes);
  std::copy_n(e.load.node.begin(), n, d.load.node.begin());
  std::copy_n(e.load.slot.begin(), n, d.load.slot.begin());
  std::copy_n(e.load.weight.begin(), n, d.load.weight.begin());
  d.has_gradient = e.has_gradient;
  if (e.has_gradient) std::copy_n(e.gradient.begin(), n, d.gradient.begin());
}

// Phase "rows", a kept row's spread (SimulationOptions::contact_spread): the unit load spread
// about its point at rest (ContactSurface::spread; its triangle's nodes if the spread finds none),
// its nodes' normals, and the tiers' offset along them added to its rest depth. False if the row
// rests on fixed nodes only. A row without a pending spread is left as it is.
bool State::spread_row(const Model& m, Row& r) {
  if (!r.spread_pending) return true;
  r.spread_pending = false;
  // The same inputs as a spread of the last or of this geometry (bit for bit): its load.
  bool from_last = false;
  const SpreadMemo* memo = find_spread(r, &from_last);
  // A sliding row's weight gradient is made with its load (normal_turn reads it from the memo).
  const bool slides = !tier_ && !r.point_slide.isZero(0.0);
  bool found;
  const SpreadLoad* load = &spread_load_;  // (the memo's read in place, not copied)
  if (memo && (memo->has_gradient || !slides)) {
    found = memo->found;
    load = &memo->load;
    // Carried into this geometry's memo, so the next geometry finds it too (a held tool's rows
    // repeat for many steps: else spread again every second step).
    last_spread_ = memo;
    if (from_last) add_spread(*memo);
  } else {
    found = m.bodies_[r.body].surface.spread(r.spread_at_m, r.spread_normal, r.spread_radius_m,
                                             spread_triangles_, spread_load_,
                                             slides ? &spread_gradient_ : nullptr);
    if (spread_memo_.size() < spread_memo_.capacity()) {
      spread_keys_.push_back(
          spread_key(r.body, r.spread_at_m, r.spread_normal, r.spread_radius_m));
      SpreadMemo& e = spread_memo_.emplace_back();
      e.body = r.body;
      e.at_m = r.spread_at_m;
      e.normal = r.spread_normal;
      e.radius_m = r.spread_radius_m;
      e.found = found;
      if (found) e.load = spread_load_;
      e.has_gradient = found && slides;
      if (e.has_gradient) e.gradient = spread_gradient_;
      last_spread_ = &e;
    }
  }
  if (found) {
    r.nodes = load->nodes;
    for (int k = 0; k < r.nodes; ++k) {
      r.slot[k] = load->slot[k];
      r.w[k] = load->weight[k];
    }
  } else {
    r.spread_radius_m = 0.0;
  }
  const TierLinearization* lin = tier_ ? &tier_->linearization(r.body) : nullptr;
  Vec3 offset = Vec3::Zero();
  if (!row_node_normals(r, lin, offset)) return false;
  r.rest_depth_m += r.normal.dot(offset);
  return true;
}

namespace {

// The near field's material under a part (its deepest row on the body): the mesh carrying that
// row's largest weight, the body's host or an exposed tied mesh (CoupledBody::expose_tie: a
// vessel leaving the brain is indented with its own E and nu, not the brain's).
const fem::Material& near_field_material(const Model& m, int body, const Row* deepest) {
  const BodyModel& b = m.bodies_[body];
  if (deepest == nullptr || !b.body->has_exposed_contact()) return b.host_material;
  int slot = -1;
  double heaviest = -1.0;
  for (int p = 0; p < deepest->nodes; ++p) {
    if (deepest->slot[p] >= 0 && deepest->w[p] > heaviest) {
      heaviest = deepest->w[p];
      slot = deepest->slot[p];
    }
  }
  if (slot < 0) return b.host_material;
  const CoupledBody::ContactPoint p = b.body->contact_point(slot);
  if (p.slide >= 0) return b.body->exposed_slide(p.slide)->material();
  return p.tie < 0 ? b.host_material : b.body->ties()[static_cast<std::size_t>(p.tie)].material();
}

}  // namespace

// SimulationOptions::contact_near_field, per body the tool's tip rows: the compliance the
// mesh cannot show under a contact patch smaller than its cells, in series with all of them
// (the tip's local indentation grows with the sum of its rows' forces): Hertz's secant
// compliance at the tip's depth d (its deepest row), 3 / (4 E* a) with a = sqrt(R d), less the
// half-space's compliance under the load the rows carry: the tip's patch, each row's share of it
// spread over rho (the row's spread radius) about its point, k / (E* sqrt(rho^2 + q a^2)).
// k = 0.766 is the work-conjugate mean displacement of the spread pressure (1 - s^2 / rho^2)^2
// alone (Monte Carlo; a uniform disk's is 16 / (3 pi^2) = 0.540); a pressure's compliance goes
// as 1 / its rms radius (the two profiles: 0.383 / (E* s_rms), s_rms = rho / 2, and the Hertz
// pressure's 0.379, s_rms = sqrt(2/5) a) and a spread patch's mean square radius is the sum of
// the two, so rho^2 + q a^2; q = (0.766 / 0.75)^2 = 1.043 makes the term Hertz's own once the
// spread is small against the patch (rho -> 0: cells finer than the patch, the rows sample the
// sphere themselves). So c = (0.75 / a - 0.766 / sqrt(rho^2 + q a^2)) / E* >= 0: the former
// rule's 0.766 / rho for rho >> a (the patch within the spread), vanishing smoothly as the
// cells shrink below the patch, where the former max(0, 0.75 / a - 0.766 / rho) left the
// spread's smear uncorrected for a > 0.98 rho (the 2 mm tip 1 mm into the block graded to 1 mm
// cells: 11.4 mN against 8.4 now, Sneddon 6.7; bench/RESULTS.md, "The near field of a patch
// wider than the spread"). E* = E / (1 - nu^2) of the mesh under the tip (near_field_material).
// Large at first touch (d -> 0), so a tip's force grows from zero with the depth.
void State::near_field_of_tool(const Model& m, const ToolShape& shape) {
  if (!m.options_.contact_near_field) return;
  // One pass per body over the tool's rows (a few bodies, tens of rows).
  for (int body = 0; body < static_cast<int>(m.bodies_.size()); ++body) {
    double depth = 0.0, rho = 0.0;
    bool any = false;
    Row* deepest = nullptr;
    for (Row& r : tool_rows_) {
      if (r.shaft || r.body != body || !r.kept) continue;
      any = true;
      if (!(r.depth_m > depth)) continue;
      depth = r.depth_m;
      rho = r.spread_radius_m;
      deepest = &r;
    }
    if (!any) continue;
    const fem::Material& mat = near_field_material(m, body, deepest);
    const double e_star =
        mat.youngs_modulus_pa / (1.0 - mat.poisson_ratio * mat.poisson_ratio);
    const double radius = shape.tip_radius_m;
    const double a = std::sqrt(radius * std::max(depth, 1e-4 * radius));
    constexpr double kSpread = 0.766, kHertz = 0.75, kQ = (kSpread / kHertz) * (kSpread / kHertz);
    const double patch = std::sqrt(rho * rho + kQ * a * a);  // the spread patch's radius, unit m
    const double c =
        rho > 0.0 ? std::max(0.0, (kHertz / a - kSpread / patch) / e_star) : 0.0;
    for (Row& r : tool_rows_)
      if (!r.shaft && r.body == body) r.near_field_m_per_n = c;
    // d c / d depth = (-kHertz / a + kSpread q a^2 / patch^3) / (2 d E*) (a^2 = R d).
    if (deepest != nullptr && c > 0.0 && depth > 1e-4 * radius) {
      deepest->near_field_deepest = true;
      deepest->near_field_slope_per_n =
          (-kHertz / a + kSpread * kQ * a * a / (patch * patch * patch)) / (2.0 * depth * e_star);
      // LINEAR: c's whole gradient in the tool's translation, the deepest row's depth changing by
      // -(n + depth_slide + turn^T d) . x (a node or edge row's normal turns, the smooth row's
      // depth is to the flat surface), unsymmetrized as the shaft's (near_field_of_shaft). The
      // symmetrized -n put the antisymmetric part of (K_b F_b) n^T into K: the 1 mm tip 0.75 mm
      // into the fine block by a vertex, K_xz -0.393 / K_zx -0.316 N/m against the force's
      // -0.322 / -0.387 (bench/RESULTS.md, "The tip's K against central differences").
      if (!tier_) {
        const Row& d = *deepest;
        deepest->near_field_gradient =
            -d.near_field_slope_per_n * (d.normal + d.depth_slide + d.turn_depth);
      }
    }
  }
}

// SimulationOptions::contact_shaft_near_field, per body the shaft's rows: as the tip's near field
// (near_field_of_tool) for the capsule's patch, in series with all of the shaft's rows on the
// body (their summed force indents the capsule's patch): c = patch_near_field(a, b, rho) with
// the patch of the deepest shaft row (tool_geometry.hpp shaft_patch: its depth d, the tilt of
// the axis to its normal), rho its spread radius. Tied to the mesh as the tip's: the spread
// radius is contact_spread times the local edge, faded out where the edge is below the shaft's
// radius (merge_features), and c -> 0 as rho shrinks below the patch. The tangent (answer) takes
// c's change with d (the tilt held), by a central difference of the closed form. Not on a
// relaxing body (BodyState::near_field_history follows the tip's force only).
void State::near_field_of_shaft(const Model& m, const ToolShape& shape, const Vec3& axis) {
  if (!m.options_.contact_near_field || !m.options_.contact_shaft_near_field) return;
  if (!(shape.shaft_radius_m > 0.0) || !(shape.shaft_length_m > 0.0)) return;
  for (int body = 0; body < static_cast<int>(m.bodies_.size()); ++body) {
    if (bodies_[body].near_field_history) continue;
    Row* deepest = nullptr;
    for (Row& r : tool_rows_)
      if (r.shaft && r.body == body && r.kept &&
          (deepest == nullptr || r.depth_m > deepest->depth_m))
        deepest = &r;
    if (deepest == nullptr || !(deepest->depth_m > 0.0)) continue;
    const fem::Material& mat = near_field_material(m, body, deepest);
    const double e_star =
        mat.youngs_modulus_pa / (1.0 - mat.poisson_ratio * mat.poisson_ratio);
    const double sin_tilt = deepest->normal.dot(axis);
    const double rho = deepest->spread_radius_m;
    auto compliance = [&](double d) {
      double a = 0.0, b = 0.0;
      shaft_patch(d, sin_tilt, shape.shaft_radius_m, shape.shaft_length_m, a, b);
      return patch_near_field(a, b, rho, e_star);
    };
    const double depth = deepest->depth_m;
    const double c = compliance(depth);
    if (!(c > 0.0)) continue;
    for (Row& r : tool_rows_)
      if (r.shaft && r.body == body) r.near_field_m_per_n = c;
    if (depth > 1e-4 * shape.shaft_radius_m) {
      const double h = 1e-4 * depth;
      deepest->near_field_deepest = true;
      deepest->near_field_slope_per_n = (compliance(depth + h) - compliance(depth - h)) / (2.0 * h);
      // LINEAR: c's whole gradient in the tool's translation. The deepest row's depth changes by
      // -(n + depth_slide + turn^T d) . x (its centre slides along the axis, an edge's point
      // along the edge, its normal turns: merge_features), not -n . x, and the tilt sin = n . u
      // by (turn^T u) . x. With -n alone, K along the tilted shaft's own axis read -0.6 to -1.8
      // N/m where moving the tool along it leaves the force unchanged (the fine block, shaft
      // 6-20 degrees; bench/RESULTS.md, "The tilted shaft's K against central differences").
      if (!tier_) {
        const double hs = 1e-4;
        auto tilted = [&](double s) {
          double a = 0.0, b = 0.0;
          shaft_patch(depth, s, shape.shaft_radius_m, shape.shaft_length_m, a, b);
          return patch_near_field(a, b, rho, e_star);
        };
        const double tilt_slope = (tilted(sin_tilt + hs) - tilted(sin_tilt - hs)) / (2.0 * hs);
        const Row& d = *deepest;
        deepest->near_field_gradient =
            -d.near_field_slope_per_n * (d.normal + d.depth_slide + d.turn_depth) +
            tilt_slope * (d.turn.transpose() * axis);
      }
    }
  }
}

// SimulationOptions::contact_near_field, the tool's stiffness: a part's near-field compliance c
// (the tip's, and with contact_shaft_near_field the shaft's) is a function of the part's depth d
// (its deepest row on the body), so the force's tangent is stiffer than -N W_AA^-1 N^T with c
// held: dF/dx = K + (dF/dc)(dc/dd)(dd/dx) with dF/dc = K_b F_b, F_b the force of the part's rows
// on the body and K_b = -N W_AA^-1 N_b^T the tool's force per unit force along those rows
// (W's change is M M^T over them: exact), and dd/dx = -n of the deepest row; symmetrized (the
// client's K). K_b is K itself when the part's rows on the body are all the tool's active
// rows (the usual case); with the shaft's rows also active, K in its place counted the shaft's
// response to the tip's near field: K 1.62x the force's finite difference (2 mm tip 1.5 mm
// into 12 mm cells, its shaft 10 degrees off the face; simulation_test). For one row it is
// 1/C + c_h/(2 C^2), C the row's compliance, c_h Hertz's secant: on the interaction tests'
// block (a 15 mm tip 3 mm into 12 mm cells, c_h / C = 0.95) a finite difference of the force
// was 1.47x the K without it.
void State::near_field_tangent(int t, int ns, int tools, Mat3& k) {
  const int nc = static_cast<int>(rows_.size());
  const Mat3 k0 = k;
  if (k0.isZero(0.0)) return;  // no active row, or own_stiffness found W not definite
  for (int r = 0; r < nc; ++r) {
    const Row& d = rows_[r];
    if (d.tool != t || !d.near_field_deepest || d.near_field_slope_per_n == 0.0) continue;
    Vec3 f_b = Vec3::Zero();
    bool others = false;  // active rows of the tool outside the part's on the body
    for (int s = 0; s < nc; ++s) {
      const Row& q = rows_[s];
      const double l = lambda_[ns + s];
      if (q.tool != t || !(l > 0.0)) continue;
      if (q.shaft == d.shaft && q.body == d.body) {
        f_b += l * q.normal;
      } else {
        others = true;
      }
    }
    // Relaxing: c multiplies the creep-equivalent force alpha F_b - h (on the tool; the tip's).
    if (!d.shaft) {
      double alpha = 1.0;
      const Vec3 h = near_field_creep(d.body, t, alpha);
      f_b = alpha * f_b - h;
    }
    const Vec3 kf = others ? part_response(t, ns, tools, d, f_b) : Vec3(k0 * f_b);
    // LINEAR: c's whole gradient (near_field_of_tool, near_field_of_shaft), not symmetrized: the
    // symmetric part put -(dc/dd) n (kf . u) along the tilted shaft's axis u, where the force does not
    // change (with -n as the gradient, symmetrized: the fine block's shaft at 45 degrees K u
    // -0.9 N/m; bench/RESULTS.md, "The tilted shaft's K against central differences").
    if (!d.near_field_gradient.isZero(0.0)) {
      k.noalias() += kf * d.near_field_gradient.transpose();
      continue;
    }
    const Mat3 term = -d.near_field_slope_per_n * kf * d.normal.transpose();
    k += 0.5 * (term + term.transpose());
  }
}

// K_b f: the tool's force per the force f pushed along the rows of part b (d's part and body),
// -N W_AA^-1 N_b^T f over the tool's active rows (near_field_tangent). One tool: the LCP's
// active inverse; several: own_stiffness's factor L of this answer (K = -Y^T Y, L Y = N), so
// -Y^T z with L z = N_b^T f (near_field_tangent skips a K that own_stiffness left zero).
Vec3 State::part_response(int t, int ns, int tools, const Row& d, const Vec3& f) {
  if (tools == 1) {
    const Mat3 kb = lcp_.contact_stiffness(
        ns,
        [&](int row) -> const Vec3* {
          const Row& q = rows_[row - ns];
          return q.tool == t ? &q.normal : nullptr;
        },
        [&](int row) -> const Vec3* {
          const Row& q = rows_[row - ns];
          return q.tool == t && q.shaft == d.shaft && q.body == d.body ? &q.normal : nullptr;
        });
    return kb * f;
  }
  const int n = static_cast<int>(own_rows_.size());
  Vec3 out = Vec3::Zero();
  for (int i = 0; i < n; ++i) {
    const Row& q = rows_[own_rows_[i]];
    double v = q.shaft == d.shaft && q.body == d.body ? q.normal.dot(f) : 0.0;
    for (int j = 0; j < i; ++j) v -= own_factor_(i, j) * own_z_[j];
    own_z_[i] = v / own_factor_(i, i);
    out -= own_z_[i] * own_y_.row(i).transpose();
  }
  return out;
}

// Phase "near field" (after Delassus): the tip's near-field compliance in series with its rows,
// W_rs += alpha c n_r . n_s over the tip rows r, s of one tool on one body (positive
// semidefinite: W stays definite); the shaft's (near_field_of_shaft) likewise over the shaft's
// rows, elastic (alpha 1, no history). A relaxing body: the near field is a compliance c in series
// with the mesh's, so it follows the same hereditary law (viscoelastic_history.hpp): its
// displacement is c times the creep-equivalent force F~ = int J(t - s) dF(s) of the tip's total
// force F on the body, F~_n = alpha F_n + h_n with the tool's own internal variables
// (BodyState::near_field_history): alpha c in W, and c h_n along each row's normal in its depth,
// as the mesh's C h_n. With c held (a held depth) the series pair relaxes exactly as the kernel
// g; with c(d) changing along a path the force is int g(t - s) dF_el(s), F_el the elastic force
// along that path (F~ is the elastic answer at each depth, J and g inverse).
void State::near_field(int ns) {
  const int nc = static_cast<int>(rows_.size());
  for (int r = 0; r < nc; ++r) {
    const Row& a = rows_[r];
    if (!(a.near_field_m_per_n > 0.0)) continue;
    double alpha = 1.0;
    double c = a.near_field_m_per_n;  // the shaft's: elastic (near_field_of_shaft)
    if (!a.shaft) {
      const Vec3 h = near_field_creep(a.body, a.tool, alpha);
      c *= alpha;
      delta_[ns + r] += a.near_field_m_per_n * a.normal.dot(h);
    }
    for (int s = r; s < nc; ++s) {
      const Row& b = rows_[s];
      if (b.shaft != a.shaft || b.tool != a.tool || b.body != a.body) continue;
      const double v = c * a.normal.dot(b.normal);
      w_(ns + r, ns + s) += v;
      if (s != r) w_(ns + s, ns + r) += v;
    }
  }
}

// The near field's step on a relaxing body, as the mesh's: in the LINEAR tier the creep form
// (the mesh's, a force linear over the step: alpha and h of the history); in the NONLINEAR tier,
// whose quasi-linear equilibrium relaxes with the displacement held between updates, the
// relaxation form (F~ linear over the step: alpha = 1 / gamma, h = -r / gamma,
// ViscoelasticHistory::relaxation_gamma). With the creep form there a held press stepped from
// 0.1 s to 1e4 s (a 1000 s term) ended at 0.163 F(0) against g = 0.200: a force linear over a
// step 10x the creep time is not the relaxing force of a held pose.
Vec3 State::near_field_creep(int body, int tool, double& alpha) const {
  alpha = 1.0;
  const ViscoelasticHistory* hist = near_field_history(body, tool);
  if (hist == nullptr) return Vec3::Zero();
  if (bodies_[body].history) {
    alpha = hist->alpha();
    return hist->force_of(tool);
  }
  alpha = 1.0 / hist->relaxation_gamma();
  return -alpha * hist->relaxation_history(tool);
}

// Phase "compliance columns": the coupled columns of every node a row acts on (cached after the
// first touch; block solves, milliseconds, inside the step), or, with the column worker, the
// fallback for those it has not solved yet (no solve in the step).
void State::compliance_columns(StepStats& stats) {
  if (column_worker_) {
    columns_fallback(stats);
    return;
  }
  for (auto& list : missing_) list.clear();
  for (const Row& r : rows_)
    for (int k = 0; k < r.nodes; ++k)
      if (r.slot[k] >= 0 && !bodies_[r.body].columns->has(r.slot[k]))
        missing_[r.body].push_back(r.slot[k]);
  stats.columns_computed = 0;
  for (std::size_t bi = 0; bi < bodies_.size(); ++bi) {
    if (missing_[bi].empty()) continue;
    const std::size_t before = bodies_[bi].columns->size();
    bodies_[bi].columns->ensure(missing_[bi]);
    stats.columns_computed += static_cast<int>(bodies_[bi].columns->size() - before);
  }
}

// Column worker: a row node whose columns are not ready yet (counted once per geometry) carries
// nothing this step and its barycentric weight moves to the row's ready nodes, in proportion to
// theirs (the point is held by the part of its triangle whose compliance is known: the nearest
// ready nodes); a row with no ready node (a node row, or a triangle none of whose nodes is
// ready) is left out of this step. Passive and bounded: the rows left act on nodes of the real
// body with known columns, so W = H C H^T (+ the row compliance in series) stays positive
// definite and the LCP solvable, and the forces are those of the elastic body loaded at those
// nodes (it stores the tool's work and gives it back, no more); a row left out can only lower
// the force. When the columns arrive the row switches to its own nodes (a change of compliance
// between neighbouring nodes at the same depth). The rows keep their order (deterministic for
// a given set of ready slots).
void State::columns_fallback(StepStats& stats) {
  stats.columns_computed = 0;
  stats.columns_not_ready = 0;
  const long long g = geometry_counter_;
  std::size_t kept = 0;
  for (std::size_t r = 0; r < rows_.size(); ++r) {
    Row row = rows_[r];
    const ContactColumns& cols = *bodies_[row.body].columns;
    double ready_w = 0.0, missing_w = 0.0;
    for (int k = 0; k < row.nodes; ++k) {
      const int s = row.slot[k];
      if (s < 0) continue;
      if (cols.has(s)) {
        ready_w += row.w[k];
        continue;
      }
      missing_w += row.w[k];
      long long& stamp = not_ready_stamp_[row.body][s];
      if (stamp != g) {
        stamp = g;
        ++stats.columns_not_ready;
      }
      row.slot[k] = -1;  // carries nothing (as a fixed node)
      row.w[k] = 0.0;
    }
    if (missing_w > 0.0) {
      if (!(ready_w > 0.0)) continue;  // no ready node: the row waits for its columns
      const double scale = (ready_w + missing_w) / ready_w;
      for (int k = 0; k < row.nodes; ++k)
        if (row.slot[k] >= 0) row.w[k] *= scale;
    }
    rows_[kept++] = row;
  }
  rows_.resize(kept);
}

// Phase "Delassus": W_rs = sum_a sum_b w_ra w_sb m_ra . L(a, b) m_sb (coupled compliance, unit
// m/N; m = R^T n per node, n in LINEAR) with the row compliance in series on the diagonal;
// against the sliding rows of the same body W_kr = -sum_a w_ra J_A,k L[:, a] m_ra; delta the
// rows' depths. The rows of a patch share nodes: sum_p w_rp L(slot_rp, b)^T m_rp is formed once
// per row and node b (not once per row pair), the same sums in the same order as per pair.
void State::delassus(const Model& m, int ns) {
  delassus_nodes();
  const bool reuse = delassus_match();
  delassus_cache_lookup(reuse);
  delassus_y();
  delassus_fill(m, ns);
  // This W's rows, their v and y cache entries: the next W's match (delassus_match).
  delassus_prev_rows_.assign(rows_.begin(), rows_.end());
  delassus_prev_v_.swap(delassus_v_);
  delassus_prev_entry_.assign(delassus_row_entry_.begin(), delassus_row_entry_.end());
  delassus_prev_generation_.clear();
  for (int e : delassus_prev_entry_)
    delassus_prev_generation_.push_back(e >= 0 ? delassus_cache_[e].generation : -1);
}

// Phase "Delassus", the rows' distinct nodes (rows of one patch share them): per row node its
// index (delassus_row_node_), per node its (body, slot) and the last row on it.
void State::delassus_nodes() {
  const int nc = static_cast<int>(rows_.size());
  delassus_nodes_.clear();
  delassus_last_row_.clear();
  delassus_row_node_.resize(nc);
  for (int r = 0; r < nc; ++r) {
    const Row& a = rows_[r];
    for (int p = 0; p < a.nodes; ++p) {
      int j = -1;
      if (a.slot[p] >= 0) {
        int& index = delassus_node_[a.body][a.slot[p]];
        if (index < 0) {
          index = static_cast<int>(delassus_nodes_.size());
          delassus_nodes_.emplace_back(a.body, a.slot[p]);
          delassus_last_row_.push_back(r);
        }
        j = index;
        delassus_last_row_[j] = r;
      }
      delassus_row_node_[r][p] = j;
    }
  }
  for (const auto& [body, slot] : delassus_nodes_) delassus_node_[body][slot] = -1;
}

// Phase "Delassus", reuse: each row matched to a row of the last W equal to it bit for bit
// (delassus_match_, -1: none), in the last W's order; the unmatched rows and per node the last
// unmatched row on it. False if a body's columns evicted slots since the last W (no match).
bool State::delassus_match() {
  const int nc = static_cast<int>(rows_.size());
  const int nn = static_cast<int>(delassus_nodes_.size());
  // The rows equal to a row of the last W (none if a body's columns evicted since).
  bool reuse = true;
  for (std::size_t bi = 0; bi < bodies_.size(); ++bi) {
    const std::uint64_t e = bodies_[bi].columns ? bodies_[bi].columns->evicted() : 0;
    if (e != delassus_evicted_[bi]) reuse = false;
    delassus_evicted_[bi] = e;
  }
  const int np = reuse ? static_cast<int>(delassus_prev_rows_.size()) : 0;
  delassus_match_.assign(nc, -1);
  for (int r = 0; r < nc; ++r) {
    const Row& a = rows_[r];
    for (int q = 0; q < np; ++q) {
      const Row& b = delassus_prev_rows_[q];
      if (b.key != a.key || b.body != a.body || b.nodes != a.nodes) continue;
      const std::size_t n = static_cast<std::size_t>(a.nodes);
      if (std::memcmp(a.slot.data(), b.slot.data(), n * sizeof(int)) == 0 &&
          std::memcmp(a.w.data(), b.w.data(), n * sizeof(double)) == 0 &&
          std::memcmp(a.m.data(), b.m.data(), n * sizeof(Vec3)) == 0) {
        delassus_match_[r] = q;
        break;
      }
    }
  }
  // v_rs (r < s) is formed from y_r: a kept v of two rows that were in the other order was formed
  // from y_s (another rounding: a fresh State's W differed at round-off). So the matches keep the
  // last W's order: a row matched to an earlier row of the last W than a row before it matched is
  // formed again (tools trading places in the pose list, a tool's rows in a new depth order).
  for (int r = 0, last = -1; r < nc; ++r) {
    if (delassus_match_[r] < 0) continue;
    if (delassus_match_[r] > last) {
      last = delassus_match_[r];
    } else {
      delassus_match_[r] = -1;
    }
  }
  delassus_last_fresh_row_.assign(nn, -1);
  delassus_unmatched_.clear();
  delassus_row_body_.clear();
  for (int s = 0; s < nc; ++s) {
    delassus_row_body_.push_back(rows_[s].body);
    if (delassus_match_[s] >= 0) continue;
    delassus_unmatched_.push_back(s);
    for (int q = 0; q < rows_[s].nodes; ++q)
      if (delassus_row_node_[s][q] >= 0) delassus_last_fresh_row_[delassus_row_node_[s][q]] = s;
  }
  return reuse;
}

// Phase "Delassus", y_rj per row r and node j (delassus_y_, row-major by node).
void State::delassus_y() {
  const int nn = static_cast<int>(delassus_nodes_.size());
  // y_rj for the nodes j of the rows s >= r on the row's body, node by node: the blocks L(., j)
  // of node j's column stay in cache while every row reads them (row by row, each row read all
  // the nodes' columns again: a cache miss per block, 24 % of four probes' step). A matched row
  // needs y_rj only against the unmatched rows. From the y cache where it holds the row's
  // content and the node, else formed and kept there.
  // The cache is node-major (a node's entries adjacent: one node read against every row), and the
  // rows that form y_rj fresh have their blocks fetched first, all at once (the loads of one row
  // after another waited on memory: the first multiply after a block's load held 39 % of the
  // phase's samples).
  for (int j = 0; j < nn; ++j) {
    const auto& [body, slot_q] = delassus_nodes_[j];
    const auto& cols = *bodies_[body].columns;
    const int cj = delassus_node_entry_[j];
    DelassusY* const kept = cj >= 0 ? delassus_cache_y_.data() +
                                          static_cast<std::size_t>(cj) * delassus_cache_rows_
                                    : nullptr;
    delassus_fresh_.clear();
    // The rows r <= last_row[j] on the body, a matched one only up to the node's last unmatched
    // row: every row up to that, then the unmatched rows after it (ascending r).
    auto visit = [&](int r) {
      if (delassus_row_body_[r] != body) return;
      const long long g = delassus_row_generation_[r];
      if (kept && g >= 0 && kept[delassus_row_entry_[r]].stamp == g) {
        delassus_y_[static_cast<std::size_t>(r) * nn + j] = kept[delassus_row_entry_[r]].y;
        return;
      }
      delassus_fresh_.push_back(r);
      const Row& a = rows_[r];
      for (int p = 0; p < a.nodes; ++p) {
        if (a.slot[p] < 0) continue;
        const double* b = cols.block(a.slot[p], slot_q).data();
        __builtin_prefetch(b);
        __builtin_prefetch(b + 8);
      }
    };
    const int last = delassus_last_row_[j];
    const int all_up_to = std::min(last, delassus_last_fresh_row_[j]);
    for (int r = 0; r <= all_up_to; ++r) visit(r);
    for (const int r : delassus_unmatched_) {
      if (r > last) break;
      if (r > all_up_to) visit(r);
    }
    for (const int r : delassus_fresh_) {
      const Row& a = rows_[r];
      Vec3 y = Vec3::Zero();  // sum_p w_p L(slot_p, slot_q)^T m_p
      for (int p = 0; p < a.nodes; ++p)
        if (a.slot[p] >= 0) y.noalias() += a.w[p] * (cols.block(a.slot[p], slot_q).transpose() * a.m[p]);
      delassus_y_[static_cast<std::size_t>(r) * nn + j] = y;
      const int e = delassus_row_entry_[r];
      if (e >= 0 && kept) kept[e] = DelassusY{y, delassus_cache_[e].generation};
    }
  }
}

// Phase "Delassus", W and delta: per row its depth (with a relaxing body's history displacement)
// and v_rs against the rows s >= r (the last W's where both rows matched, else from y), times
// alpha, with the row compliance on the diagonal; then its column against the sliding rows.
void State::delassus_fill(const Model& m, int ns) {
  const int nc = static_cast<int>(rows_.size());
  const int nn = static_cast<int>(delassus_nodes_.size());
  const double eps = m.options_.contact_row_compliance;
  // Viscoelastic: the history's displacement C h at each distinct node of the rows, once
  // (BodyState::history_u_m, stamped with this geometry; normal_turn's U_k reads it too).
  for (const auto& [body, slot] : delassus_nodes_) {
    BodyState& bs = bodies_[body];
    if (!bs.history || bs.history->slots().empty()) continue;
    bs.history_u_m[slot] = bs.history->displacement(*bs.columns, slot);
    bs.history_u_stamp[slot] = geometry_counter_;
  }
  for (int r = 0; r < nc; ++r) {
    const Row& a = rows_[r];
    const int i = ns + r;
    const BodyState& bs = bodies_[a.body];
    const ViscoelasticHistory* hist = bs.history.get();
    delta_[i] = a.rest_depth_m;
    // Viscoelastic: the history's displacement moves the surface (depth + its share along m),
    // and the step's compliance is alpha W (viscoelastic_history.hpp).
    const double alpha = hist ? hist->alpha() : 1.0;
    if (hist && !hist->slots().empty())
      for (int p = 0; p < a.nodes; ++p)
        if (a.slot[p] >= 0) delta_[i] += a.w[p] * a.m[p].dot(bs.history_u_m[a.slot[p]]);
    for (int s = r; s < nc; ++s) {
      const Row& c = rows_[s];
      double v = 0.0;
      if (delassus_match_[r] >= 0 && delassus_match_[s] >= 0) {
        v = delassus_prev_v_(delassus_match_[r], delassus_match_[s]);
      } else if (c.body == a.body) {
        const mesh::Vec3* yr = delassus_y_.data() + static_cast<std::size_t>(r) * nn;
        for (int q = 0; q < c.nodes; ++q) {
          if (c.slot[q] < 0) continue;
          v += c.w[q] * yr[delassus_row_node_[s][q]].dot(c.m[q]);
        }
      }
      delassus_v_(r, s) = v;
      delassus_v_(s, r) = v;
      v *= alpha;
      if (s == r) v *= 1.0 + eps;
      w_(i, ns + s) = v;
      w_(ns + s, i) = v;
    }
    if (ns > 0) delassus_sliding(m, ns, r);
  }
}

// Phase "Delassus", row r's column against the sliding rows of its body, W_kr = -sum_a w_ra
// J_A,k L[:, a] m_ra, and its terms per node for the LCP (column_terms_).
void State::delassus_sliding(const Model& m, int ns, int r) {
  const Row& a = rows_[r];
  const int i = ns + r;
  const auto& cols = *bodies_[a.body].columns;
  w_.col(i).head(ns).setZero();
  const int rows_a = m.bodies_[a.body].body->sliding().size();
  for (int p = 0; p < kSpreadNodes; ++p)
    column_terms_[kSpreadNodes * static_cast<std::size_t>(r) + p] = LcpColumnTerm{};
  if (rows_a > 0) {
    const int o = m.bodies_[a.body].sliding_offset;
    for (int p = 0; p < a.nodes; ++p) {
      if (a.slot[p] < 0) continue;
      const ContactColumns::Columns& sb = cols.sliding_block(a.slot[p]);
      w_.col(i).segment(o, rows_a).noalias() -= a.w[p] * (sb * a.m[p]);
      LcpColumnTerm& term = column_terms_[kSpreadNodes * static_cast<std::size_t>(r) + p];
      term.block = sb.data();
      term.key = (static_cast<std::uint64_t>(a.body) << 32) | static_cast<std::uint32_t>(a.slot[p]);
      term.offset = o;
      term.length = rows_a;
      term.coef = -a.w[p] * a.m[p];
    }
  }
  w_.row(i).head(ns) = w_.col(i).head(ns).transpose();
}

// Phase "Delassus", the y cache's entries of this W's rows and indices of its nodes (after the
// match with the last W's rows). reuse false (a body's columns evicted slots since the last W):
// every entry's values are given up. Allocates nothing (reserved).
void State::delassus_cache_lookup(bool reuse) {
  const int nc = static_cast<int>(rows_.size());
  const int nn = static_cast<int>(delassus_nodes_.size());
  const long long now = ++delassus_counter_;
  const long long held = delassus_generation_;  // every kept value's generation is at most this
  auto flush_values = [&] {
    for (auto& e : delassus_cache_) e.generation = ++delassus_generation_;
  };
  if (!reuse) flush_values();
  // Nodes: every node of this W gets an index unless this W alone has more than the cache holds;
  // a full cache gives up all its nodes and values first.
  int fresh = 0;
  for (const auto& [body, slot] : delassus_nodes_)
    if (delassus_cache_node_[body][slot] < 0) ++fresh;
  if (fresh > 0 && static_cast<int>(delassus_cache_nodes_.size()) + fresh > kDelassusCacheNodes) {
    for (const auto& [body, slot] : delassus_cache_nodes_) delassus_cache_node_[body][slot] = -1;
    delassus_cache_nodes_.clear();
    flush_values();
  }
  delassus_node_entry_.resize(nn);
  for (int j = 0; j < nn; ++j) {
    const auto& [body, slot] = delassus_nodes_[j];
    int& index = delassus_cache_node_[body][slot];
    if (index < 0 && static_cast<int>(delassus_cache_nodes_.size()) < kDelassusCacheNodes) {
      index = static_cast<int>(delassus_cache_nodes_.size());
      delassus_cache_nodes_.emplace_back(body, slot);
    }
    delassus_node_entry_[j] = index;
  }
  // Rows: a matched row takes its last row's entry; any other row the entry with its content, or
  // the least recently used entry not read by this W (a new generation).
  auto same_content = [](const Row& a, const Row& b) {
    const std::size_t n = static_cast<std::size_t>(a.nodes);
    // (the normals first: a node or edge row's turn with the tool while its nodes stay)
    return a.body == b.body && a.nodes == b.nodes &&
           std::memcmp(a.m.data(), b.m.data(), n * sizeof(Vec3)) == 0 &&
           std::memcmp(a.slot.data(), b.slot.data(), n * sizeof(int)) == 0 &&
           std::memcmp(a.w.data(), b.w.data(), n * sizeof(double)) == 0;
  };
  delassus_row_entry_.resize(nc);
  for (int r = 0; r < nc; ++r) {
    const Row& a = rows_[r];
    int entry = -1;
    const int q = delassus_match_[r];
    if (q >= 0 && delassus_prev_entry_[q] >= 0 &&
        delassus_cache_[delassus_prev_entry_[q]].generation == delassus_prev_generation_[q])
      entry = delassus_prev_entry_[q];  // (its content unchanged since)
    for (int e = 0; e < delassus_cache_rows_ && entry < 0; ++e) {
      const DelassusCacheEntry& c = delassus_cache_[e];
      if (c.key == a.key && c.body == a.body && c.nodes == a.nodes &&
          same_content(a, delassus_cache_content_[e]))
        entry = e;
    }
    if (entry < 0) {
      long long oldest = now;
      for (int e = 0; e < delassus_cache_rows_; ++e)
        if (delassus_cache_[e].used < oldest) {
          oldest = delassus_cache_[e].used;
          entry = e;
        }
      if (entry >= 0) {
        DelassusCacheEntry& c = delassus_cache_[entry];
        c.key = a.key;
        c.body = a.body;
        c.nodes = a.nodes;
        c.generation = ++delassus_generation_;
        delassus_cache_content_[entry] = a;
      }
    }
    if (entry >= 0) delassus_cache_[entry].used = now;
    delassus_row_entry_[r] = entry;
  }
  // After every row's entry (a later row may take an entry an earlier one found: a new generation).
  delassus_row_generation_.resize(nc);
  for (int r = 0; r < nc; ++r) {
    const int e = delassus_row_entry_[r];
    delassus_row_generation_[r] =
        e >= 0 && delassus_cache_[e].generation <= held ? delassus_cache_[e].generation : -1;
  }
}

// Phase "forces": the last good contact forces per body and node (a row's force -lambda n on
// its nodes by w, summed per node), the sliding forces, and how far the surface moved.
void State::store_forces(const Model& m, int ns) {
  const int nc = static_cast<int>(rows_.size());
  for (std::size_t bi = 0; bi < m.bodies_.size(); ++bi) {
    const auto& b = m.bodies_[bi];
    auto& bs = bodies_[bi];
    for (int s : bs.force_slots) bs.force_index[s] = -1;
    bs.force_slots.clear();
    bs.forces_n.clear();
    const int rows_b = b.body->sliding().size();
    if (rows_b > 0) bs.sliding_lambda = lambda_.segment(b.sliding_offset, rows_b);
    if (bs.history) add_history_forces(bs);
  }
  for (int r = 0; r < nc; ++r) {
    const double l = lambda_[ns + r];
    if (l <= 0.0) continue;
    const Row& row = rows_[r];
    auto& bs = bodies_[row.body];
    const double alpha = bs.history ? bs.history->alpha() : 1.0;  // creep-equivalent force
    for (int k = 0; k < row.nodes; ++k) {
      const int s = row.slot[k];
      if (s < 0 || row.w[k] == 0.0) continue;
      if (bs.force_index[s] < 0) {
        bs.force_index[s] = static_cast<int>(bs.force_slots.size());
        bs.force_slots.push_back(s);
        bs.forces_n.push_back(Vec3::Zero());
      }
      bs.forces_n[bs.force_index[s]] -= (alpha * l * row.w[k]) * row.normal;  // inward on the tissue
    }
  }
  // The near field's creep-equivalent forces per tool: alpha times the tip's force on the tissue
  // plus the tool's history force (near_field).
  for (auto& bs : bodies_) {
    if (!bs.near_field_history) continue;
    const ViscoelasticHistory& hist = *bs.near_field_history;
    bs.near_field_tools.clear();
    bs.near_field_forces_n.clear();
    const int body = static_cast<int>(&bs - bodies_.data());
    for (int s : hist.slots()) {
      double alpha = 1.0;
      bs.near_field_tools.push_back(s);
      bs.near_field_forces_n.push_back(near_field_creep(body, s, alpha));
    }
  }
  for (int r = 0; r < nc; ++r) {
    const double l = lambda_[ns + r];
    const Row& row = rows_[r];
    auto& bs = bodies_[row.body];
    if (l <= 0.0 || row.shaft || near_field_history(row.body, row.tool) == nullptr) continue;
    auto at = std::find(bs.near_field_tools.begin(), bs.near_field_tools.end(), row.tool);
    if (at == bs.near_field_tools.end()) {
      bs.near_field_tools.push_back(row.tool);
      bs.near_field_forces_n.push_back(Vec3::Zero());
      at = bs.near_field_tools.end() - 1;
    }
    double alpha = 1.0;
    near_field_creep(row.body, row.tool, alpha);
    bs.near_field_forces_n[at - bs.near_field_tools.begin()] -= (alpha * l) * row.normal;
  }
}

// Phase "forces", after store_forces when another geometry follows (LINEAR, iterating) or the
// next step starts from this answer (the tiers): the largest displacement at the loaded nodes,
// how far that geometry's candidates may have moved. A LINEAR step's last geometry skips it
// (O(loaded nodes^2) blocks: the next step starts from rest, restore_forces(true)).
void State::largest_displacement(const Model& m) {
  for (std::size_t bi = 0; bi < m.bodies_.size(); ++bi) {
    auto& bs = bodies_[bi];
    double most = 0.0;
    for (int s : bs.force_slots) {
      Vec3 u = Vec3::Zero();
      if (tier_) {
        // The slot's node in the stacked equilibrium (a host node, or an exposed tied mesh's).
        u = tier_->linearization(static_cast<int>(bi)).displacement_m[static_cast<std::size_t>(s)];
      } else {
        for (std::size_t k = 0; k < bs.force_slots.size(); ++k)
          u.noalias() += bs.columns->block(s, bs.force_slots[k]) * bs.forces_n[k];
      }
      most = std::max(most, u.norm());
    }
    bs.max_displacement_m = most;
  }
}

// Several tools: the stiffness of one from its own active rows, -N (W_tt)^-1 N^T, the others'
// rows and the sliding rows left free. Two tools on nearly the same constraint would otherwise
// feel each other through the row compliance only (a stiffness of 1/eps): each station's model
// is that of its own contact. In-place Cholesky on a buffer sized at reserve (no allocation).
Mat3 State::own_stiffness(int ns, int t) {
  own_rows_.clear();
  for (int r = 0; r < static_cast<int>(rows_.size()); ++r)
    if (rows_[r].tool == t && lambda_[ns + r] > 0.0) own_rows_.push_back(r);
  const int n = static_cast<int>(own_rows_.size());
  Mat3 k = Mat3::Zero();
  if (n == 0) return k;
  auto& a = own_factor_;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j <= i; ++j) a(i, j) = w_(ns + own_rows_[i], ns + own_rows_[j]);
  for (int j = 0; j < n; ++j) {  // lower Cholesky factor
    double d = a(j, j);
    for (int q = 0; q < j; ++q) d -= a(j, q) * a(j, q);
    if (!(d > 0.0)) return k;  // not definite: no stiffness rather than a wrong one
    a(j, j) = std::sqrt(d);
    for (int i = j + 1; i < n; ++i) {
      double v = a(i, j);
      for (int q = 0; q < j; ++q) v -= a(i, q) * a(j, q);
      a(i, j) = v / a(j, j);
    }
  }
  // K = -sum_ij n_i (W^-1)_ij n_j^T = -Y^T Y with L Y = N (rows of N: the normals).
  auto& y = own_y_;
  for (int i = 0; i < n; ++i) {
    Vec3 v = rows_[own_rows_[i]].normal;
    for (int q = 0; q < i; ++q) v -= a(i, q) * y.row(q).transpose();
    y.row(i) = (v / a(i, i)).transpose();
  }
  for (int i = 0; i < n; ++i) k.noalias() -= y.row(i).transpose() * y.row(i);
  return k;
}

// The body carrying most of tool t's force (-1: none) and that force's sum of row forces.
int State::main_body_of(const Model& m, int t, int ns, double& sum_n) const {
  const int nc = static_cast<int>(rows_.size());
  int main = -1;
  sum_n = 0.0;
  for (std::size_t bi = 0; bi < m.bodies_.size(); ++bi) {
    double sum = 0.0;
    for (int r = 0; r < nc; ++r)
      if (rows_[r].tool == t && rows_[r].body == static_cast<int>(bi)) sum += lambda_[ns + r];
    if (sum > sum_n) {
      sum_n = sum;
      main = static_cast<int>(bi);
    }
  }
  return main;
}

// Phase "answer" of one tool: force, stiffness K = -N (W_AA^-1)_cc N^T over its active rows
// (each row's normal held: its depth changes by -n . dx; the normals' turn is added after the
// relaxation, normal_turn), normal, main mesh and nodes,
// validity radius (the contact patch: the active rows' points around their force-weighted
// centre, at least a quarter of the tip radius).
void State::answer(const Model& m, int t, const ToolPose& pose, int ns, int iterations,
                   int tools, ToolContact& c) {
  const int nc = static_cast<int>(rows_.size());
  c.force_n.setZero();
  c.stiffness_n_per_m.setZero();
  c.normal.setZero();
  c.reference_tip_m = pose.tip_m;
  c.converged = true;
  c.iterations = iterations;
  c.nodes.clear();
  c.mesh = -1;
  double best = 0.0;
  const int main_body = main_body_of(m, t, ns, best);
  Vec3 centre = Vec3::Zero();
  for (int r = 0; r < nc; ++r) {
    const Row& row = rows_[r];
    const double l = lambda_[ns + r];
    if (row.tool != t || !(l > 0.0)) continue;
    c.force_n += l * row.normal;
    if (row.body != main_body) continue;
    centre += (l / best) * row.point_m;
  }
  // The main mesh: of the main body's host, its exposed tied and sliding meshes, the one whose
  // nodes carry most of the force (CoupledBody::contact_part: each slot's mesh); its nodes.
  int main_part = -1;
  if (main_body >= 0 && m.bodies_[main_body].body->has_exposed_contact()) {
    const CoupledBody& body = *m.bodies_[main_body].body;
    double most = -1.0;
    for (int part = -1; part < body.num_parts(); ++part) {
      double share = 0.0;
      for (int r = 0; r < nc; ++r) {
        const Row& row = rows_[r];
        const double l = lambda_[ns + r];
        if (row.tool != t || row.body != main_body || !(l > 0.0)) continue;
        for (int k = 0; k < row.nodes; ++k)
          if (row.slot[k] >= 0 && body.contact_part(row.slot[k]) == part) share += l * row.w[k];
      }
      if (share > most) {
        most = share;
        main_part = part;
      }
    }
  }
  for (int r = 0; r < nc; ++r) {
    const Row& row = rows_[r];
    if (row.tool != t || !(lambda_[ns + r] > 0.0) || row.body != main_body) continue;
    const CoupledBody& body = *m.bodies_[row.body].body;
    for (int k = 0; k < row.nodes; ++k) {
      if (row.slot[k] < 0 || row.w[k] == 0.0) continue;
      if (body.contact_part(row.slot[k]) != main_part) continue;
      const int node = body.contact_point(row.slot[k]).node;
      if (std::find(c.nodes.begin(), c.nodes.end(), node) == c.nodes.end()) c.nodes.push_back(node);
    }
  }
  if (tools == 1) {
    c.stiffness_n_per_m = lcp_.contact_stiffness(ns, [&](int row) -> const Vec3* {
      const Row& r = rows_[row - ns];
      return r.tool == t ? &r.normal : nullptr;
    });
  } else {
    c.stiffness_n_per_m = own_stiffness(ns, t);
  }
  near_field_tangent(t, ns, tools, c.stiffness_n_per_m);
  c.in_contact = main_body >= 0;
  c.validity_radius_m = 0.0;
  if (c.in_contact) {
    const CoupledBody& body = *m.bodies_[main_body].body;
    c.mesh = body.part_mesh(main_part);
    double patch = 0.0;
    for (int r = 0; r < nc; ++r)
      if (rows_[r].tool == t && rows_[r].body == main_body && lambda_[ns + r] > 0.0)
        patch = std::max(patch, (rows_[r].point_m - centre).norm());
    c.validity_radius_m = std::max(patch, 0.25 * m.tools_[pose.tool].tip_radius_m);
    const double f = c.force_n.norm();
    if (f > 0.0) c.normal = c.force_n / f;
  }
  if (!c.force_n.allFinite() || !c.stiffness_n_per_m.allFinite()) {
    throw std::runtime_error("Simulation::step: non-finite contact result for tool " +
                             std::to_string(t));
  }
}

// Phase "relaxation" (after the history took the step): a viscoelastic main body's share of the
// tool's force per kernel term, and the instantaneous stiffness. Per slot the force relaxes as
// force_at + sum_i (e^{-s/tau_i} - 1) relaxing(slot, i) with its displacement held
// (viscoelastic_history.hpp); the tool takes each loaded slot's parts in the proportion of the
// slot's force it exerts (all of them when it alone loads the slot). Rows on other bodies: held.
// The LCP's compliance was alpha W (the step's relaxation over dt): K = alpha K_step is the
// stiffness at dt = 0, when every active row of the tool has that alpha (else the step's).
void State::relaxation(const Model& m, int t, int ns, ToolContact& c) {
  c.num_relaxing = 0;
  turn_scale_ = 1.0;
  if (!m.viscoelastic_ || !c.in_contact) return;
  double sum_n = 0.0;
  const int b = main_body_of(m, t, ns, sum_n);
  if (b < 0 || !bodies_[b].history) return;
  BodyState& bs = bodies_[b];
  const ViscoelasticHistory& hist = *bs.history;
  const long long stamp = ++relax_counter_;
  relax_slots_.clear();
  bool one_alpha = true;
  for (std::size_t r = 0; r < rows_.size(); ++r) {
    const Row& row = rows_[r];
    const double l = lambda_[ns + static_cast<int>(r)];
    if (row.tool != t || !(l > 0.0)) continue;
    const ViscoelasticHistory* h = bodies_[row.body].history.get();
    if ((h ? h->alpha() : 1.0) != hist.alpha()) one_alpha = false;
    if (row.body != b) continue;
    for (int k = 0; k < row.nodes; ++k) {
      const int s = row.slot[k];
      if (s < 0 || row.w[k] == 0.0) continue;
      if (bs.relax_stamp[s] != stamp) {
        bs.relax_stamp[s] = stamp;
        bs.tool_force_n[s].setZero();
        relax_slots_.push_back(s);
      }
      bs.tool_force_n[s] -= (l * row.w[k]) * row.normal;  // on the tissue
    }
  }
  const auto& kernel = hist.kernel();
  const int nk = std::min(static_cast<int>(kernel.size()), kMaxRelaxingForces);
  for (int i = 0; i < nk; ++i) c.relaxing[i] = RelaxingForce{Vec3::Zero(), kernel[i].tau_s};
  for (int s : relax_slots_) {
    const Vec3 f = hist.force_at(s);
    const double ff = f.squaredNorm();
    if (!(ff > 0.0)) continue;
    const double share = bs.tool_force_n[s].dot(f) / ff;
    for (int i = 0; i < nk; ++i) c.relaxing[i].force_n -= share * hist.relaxing(s, i);  // on the tool
  }
  c.num_relaxing = nk;
  if (one_alpha) {
    c.stiffness_n_per_m *= hist.alpha();
    turn_scale_ = hist.alpha();
  }
}

// Phase "answer", the rows' turn (after the relaxation: the force turns as it is, not scaled
// by alpha). F = sum_i lambda_i n_i and, on the active rows, W lambda = delta with
// delta_i = r - n_i . d_i (d_i the centre less the row's point at rest) and W_ij = n_i^T B_ij n_j
// (B_ij: the displacement at row i's point per force at row j's, the mesh's columns and the near
// field's c I in series). With J_i = d n_i / d x (Row::turn) and x the tool's translation:
//   dF/dx = sum_i lambda_i J_i - N^T W^-1 (N + V),
//   v_i = J_i^T (d_i + u_i) + sum_j lambda_j J_j^T B_ji n_i,
// u_i = sum_j B_ij n_j lambda_j the point's displacement (d_i + u_i the centre less the deformed
// point: the depth's change as n_i turns) and the second sum W's change as the other rows'
// forces turn (the displacement along n_i they cause). K (the LCP's -N W^-1 N^T with the near
// field's term) is the part with the normals held; this adds the rest. V is formed where W is
// that (LINEAR on the rest surface, no sliding rows; a relaxing body's W and displacement as its
// step has them: turn_coupling); elsewhere (the multirate tiers, whose rows add an equilibrium's
// offset) the first sum alone.
void State::normal_turn(const Model& m, int t, int ns, int tools, ToolContact& c) {
  const int nc = static_cast<int>(rows_.size());
  Mat3 g = Mat3::Zero();
  bool turns = false, slides = false;
  for (int r = 0; r < nc; ++r) {
    const double l = lambda_[ns + r];
    if (rows_[r].tool != t || !(l > 0.0)) continue;
    if (!rows_[r].depth_slide.isZero(0.0) || !rows_[r].point_slide.isZero(0.0)) slides = true;
    if (rows_[r].turn.isZero(0.0)) continue;
    g += l * rows_[r].turn;
    turns = true;
  }
  if (!turns && !slides) return;
  c.stiffness_n_per_m += g;
  if (tier_ || !rest_geometry_ || ns > 0) return;
  for (int i = 0; i < nc; ++i) turn_v_[i].setZero();
  for (int b = 0; b < static_cast<int>(bodies_.size()); ++b) turn_rows(t, ns, b);
  // The depth's change as the shaft's centre slides along the axis and an edge's point along
  // the edge (Row::depth_slide): delta_i changes by -(n_i + s_i) . x, not -n_i . x.
  for (int i = 0; i < nc; ++i)
    if (rows_[i].tool == t && lambda_[ns + i] > 0.0 && !rows_[i].depth_slide.isZero(0.0))
      turn_v_[i] += rows_[i].depth_slide;
  if (slide_weights(m, t, ns))
    for (int b = 0; b < static_cast<int>(bodies_.size()); ++b) slide_rows(t, ns, b);
  turn_stiffness(t, ns, tools, c);
}

// normal_turn on a relaxing body (its history): the step's compliance is alpha W and its nodes'
// displacement C f~, f~ = alpha f + h the stored creep-equivalent forces (the history's
// displacement plus the step's; store_forces), so U_k above is that displacement as it is, and
// W's terms (B: the forces' turn and slide under the other rows, the near field's c) are alpha's.
// relaxation scaled K's LCP part by alpha (the stiffness at dt = 0, every active row of the tool
// at that alpha: turn_scale_): then -N^T W^-1 V is alpha times the LCP's -N^T (alpha W)^-1 V
// with W's terms of V at alpha / alpha = 1 (dt -> 0: J(0) = 1, the force's change acts on the
// elastic compliance); else (turn_scale_ 1) the step's, each body's terms at its alpha. 1 on an
// elastic body, where nothing is scaled.
double State::turn_coupling(int body) const {
  const ViscoelasticHistory* h = bodies_[body].history.get();
  return (h ? h->alpha() : 1.0) / turn_scale_;
}

// normal_turn, U_k on a relaxing body (false: an elastic body, or the history's displacement not
// formed for this geometry; the caller sums the stored forces): the history's displacement C h at
// the node as delassus_fill formed it (BodyState::history_u_m) plus the step's forces' alone, the
// stored forces less the history's (store_forces put those first), so the history's slots, which
// may be many more than the rows' nodes, are not summed again per node.
bool State::relaxing_displacement(int b) {
  const BodyState& bs = bodies_[b];
  if (!bs.history) return false;
  // (after commit_history: the step's history forces as store_forces kept them)
  const std::size_t nh = static_cast<std::size_t>(bs.history_count);
  const std::vector<Vec3>& h = bs.history_forces_n;
  const bool any_history = nh > 0;
  if (any_history)
    for (const int k : turn_u_at_)
      if (bs.history_u_stamp[turn_nodes_[k]] != geometry_counter_) return false;
  for (const int k : turn_u_at_)
    turn_u_[k] = any_history ? Vec3(-bs.history_u_m[turn_nodes_[k]]) : Vec3::Zero();
  const ContactColumns& cols = *bs.columns;
  for (std::size_t f = 0; f < bs.force_slots.size(); ++f) {
    const Vec3 step = f < nh ? Vec3(bs.forces_n[f] - h[f]) : bs.forces_n[f];
    if (step.isZero(0.0)) continue;  // a history slot the step does not load
    const int s = bs.force_slots[f];
    for (const int k : turn_u_at_) turn_u_[k].noalias() -= cols.block(turn_nodes_[k], s) * step;
  }
  return true;
}

// turn_rows on a relaxing body (turn_coupling): the tip's near field, with its own history, is
// displaced by c F~ (F~ = alpha F - h, the creep-equivalent force on the tool: near_field, on the
// tissue -F~ as store_forces kept it, the history committed since) with alpha c in W: the tip
// part's force sum replaced by F~ and its c J^T sum scaled to alpha / turn_scale_; the shaft's
// near field is elastic (1 / turn_scale_). Unit N and m/N as the sums.
void State::turn_parts_relaxed(int t, int b, Vec3 part_force[2], Mat3 part_turn[2]) const {
  double near_alpha = 1.0;
  if (near_field_history(b, t) != nullptr) {
    near_field_creep(b, t, near_alpha);
    const BodyState& nb = bodies_[b];
    const auto at = std::find(nb.near_field_tools.begin(), nb.near_field_tools.end(), t);
    if (at != nb.near_field_tools.end())
      part_force[0] = -nb.near_field_forces_n[static_cast<std::size_t>(at - nb.near_field_tools.begin())];
  }
  if (near_alpha != turn_scale_) part_turn[0] *= near_alpha / turn_scale_;
  if (turn_scale_ != 1.0) part_turn[1] /= turn_scale_;
}

// turn_rows' node sums on body b over turn_nodes_: U_k = -sum_s C_ks f_s (the body's stored
// forces; a relaxing body's from its history's displacement, relaxing_displacement) where a
// turning row needs it, and Y_q = coupling * sum_k A_k C_kq (W's terms at a relaxing body's
// alpha), unit m and m/N.
void State::turn_node_sums(int b, double coupling) {
  const int nk = static_cast<int>(turn_nodes_.size());
  const BodyState& bs = bodies_[b];
  const ContactColumns& cols = *bs.columns;
  list_u_nodes();
  const bool compact = loaded_indices(b);
  if (!relaxing_displacement(b) && !bs.force_slots.empty()) node_displacements(b, compact);
  // (node q by node q, its sum held in registers: the same sums in the same order as k by k;
  // the blocks from the body's LoadedBlocks where the nodes fit there: the same bits)
  using Block = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>;
  LoadedBlocks& loaded = loaded_blocks_[b];
  for (int q = 0; q < nk; ++q) {
    Mat3 y = turn_y_[q];
    if (compact) {
      const int iq = loaded_node_index_[q];
      for (const int k : turn_u_at_)
        y.noalias() += turn_a_[k] * Block(loaded.block(cols, loaded_node_index_[k], iq));
    } else {
      for (const int k : turn_u_at_) y.noalias() += turn_a_[k] * cols.block(turn_nodes_[k], turn_nodes_[q]);
    }
    turn_y_[q] = y;
  }
  if (coupling != 1.0)
    for (int q = 0; q < nk; ++q) turn_y_[q] *= coupling;
}

// normal_turn, the rows' turn on body b (nothing when none of tool t's active rows on it turns):
// v_i's depth term J_i^T (d_i + u_i) and W's term sum_j lambda_j J_j^T B_ji n_i, into turn_v_.
// B_ij between two rows: their nodes' columns by the weights, sum_kq w_ik w_jq C_kq, and the
// near field's c_i I on one part of one tool. Summed node by node, not row pair by row pair
// (at a vertex 64 rows of 16 nodes: 40 % of the step was these pairs' 16 x 16 blocks): with U_k
// = -sum_s C_ks f_s the displacement at node k by the body's stored forces (every active row
// of every tool; a relaxing body's creep-equivalent forces, its history's with them),
//   u_j = sum_i lambda_i B_ji n_i = sum_k w_jk U_k + c_j sum_{i on j's part} lambda_i n_i,
//   sum_j lambda_j J_j^T B_ji n_i = sum_q w_iq M_q n_i + sum_{j on i's part} lambda_j c_j J_j^T n_i,
// M_q = sum_k A_k C_kq, A_k = sum_j lambda_j w_jk J_j^T (turn_a_): the same sums in another
// order (K as before up to round-off).
void State::turn_rows(int t, int ns, int b) {
  const int nc = static_cast<int>(rows_.size());
  bool any = false;
  for (int j = 0; j < nc && !any; ++j)
    any = rows_[j].tool == t && rows_[j].body == b && lambda_[ns + j] > 0.0 &&
          !rows_[j].turn.isZero(0.0);
  if (!any) return;
  std::vector<int>& index = turn_node_[b];
  turn_nodes_.clear();
  auto node = [&](int slot) {
    int& at = index[slot];
    if (at < 0) {
      at = static_cast<int>(turn_nodes_.size());
      turn_nodes_.push_back(slot);
      turn_u_[at].setZero();
      turn_needs_u_[at] = 0;
      turn_y_[at].setZero();
      turn_a_[at].setZero();
    }
    return at;
  };
  // Per part of the tool (tip, shaft): sum lambda_i n_i and sum lambda_j c_j J_j^T.
  Vec3 part_force[2] = {Vec3::Zero(), Vec3::Zero()};
  Mat3 part_turn[2] = {Mat3::Zero(), Mat3::Zero()};
  for (int i = 0; i < nc; ++i) {
    const Row& ri = rows_[i];
    const double li = lambda_[ns + i];
    if (ri.tool != t || ri.body != b || !(li > 0.0)) continue;
    part_force[ri.shaft ? 1 : 0].noalias() += li * ri.normal;
    const bool turning = !ri.turn.isZero(0.0);
    if (turning && ri.near_field_m_per_n > 0.0)
      part_turn[ri.shaft ? 1 : 0].noalias() += (li * ri.near_field_m_per_n) * ri.turn.transpose();
    for (int k = 0; k < ri.nodes; ++k) {
      if (ri.slot[k] < 0 || ri.w[k] == 0.0) continue;
      const int at = node(ri.slot[k]);
      if (!turning) continue;
      turn_needs_u_[at] = 1;
      turn_a_[at].noalias() += (li * ri.w[k]) * ri.turn.transpose();
    }
  }
  const double coupling = turn_coupling(b);
  turn_parts_relaxed(t, b, part_force, part_turn);
  turn_node_sums(b, coupling);
  for (int i = 0; i < nc; ++i) {
    const Row& ri = rows_[i];
    const double li = lambda_[ns + i];
    if (ri.tool != t || ri.body != b || !(li > 0.0)) continue;
    Vec3 u = Vec3::Zero(), v = part_turn[ri.shaft ? 1 : 0] * ri.normal;
    const bool turning = !ri.turn.isZero(0.0);
    for (int k = 0; k < ri.nodes; ++k) {
      if (ri.slot[k] < 0 || ri.w[k] == 0.0) continue;
      const int at = index[ri.slot[k]];
      if (turning) u.noalias() += ri.w[k] * turn_u_[at];
      v.noalias() += ri.w[k] * (turn_y_[at] * ri.normal);
    }
    turn_v_[i] += v;
    if (!turning) continue;
    // The depth's change: J_i^T (c - the deformed point), the centre being the part's.
    if (ri.near_field_m_per_n > 0.0) u.noalias() += ri.near_field_m_per_n * part_force[ri.shaft ? 1 : 0];
    turn_v_[i].noalias() += ri.turn_depth + ri.turn.transpose() * u;
  }
  for (int slot : turn_nodes_) index[slot] = -1;
}

// normal_turn, W's change as the shaft's face and edge rows' points slide over the surface (Row::
// point_slide): a spread row's weights w_k follow its point (ContactSurface::spread's gradient,
// rho and the node set held), so (W lambda)_i = n_i^T sum_k w_ik U_k (U_k the displacement at
// node k) changes by sum_k (n_i . U_k) dw_ik (row i's point sliding over the displaced
// surface) plus sum_j lambda_j sum_kq w_ik (n_i^T C_kq n_j) dw_jq (row j's load moving under
// row i). Without it the shaft 6 degrees against the fine block, 0.2 mm either side of its
// face, had K's press column 25-31 % stiffer than the force's central difference
// (bench/RESULTS.md, "The tilted shaft's K against central differences"). Here per active row
// of tool t its dw_k / dx (weight_slide_, weight_slides_); true if some row's weights move.
bool State::slide_weights(const Model& m, int t, int ns) {
  const int nc = static_cast<int>(rows_.size());
  bool weights_move = false;
  for (int i = 0; i < nc; ++i) {
    weight_slides_[i] = 0;
    const Row& r = rows_[i];
    if (r.tool != t || !(lambda_[ns + i] > 0.0) || r.point_slide.isZero(0.0)) continue;
    if (!(r.spread_radius_m > 0.0)) {
      // Its triangle's nodes by the point's barycentric weights (merge_features: weight_slide).
      if (r.nodes != 3 || r.weight_slide.isZero(0.0)) continue;
      for (int k = 0; k < 3; ++k) weight_slide_[i][k] = r.weight_slide.col(k);
      weight_slides_[i] = 1;
      weights_move = true;
      continue;
    }
    // The gradient spread_row made with the row's load (the memo), else spread again.
    const SpreadMemo* e = find_spread(r, nullptr);
    const SpreadLoad* load = &spread_load_;
    const std::array<Vec3, kSpreadNodes>* dw = &spread_gradient_;
    if (e != nullptr && e->has_gradient) {
      load = &e->load;
      dw = &e->gradient;
    } else if (!m.bodies_[r.body].surface.spread(r.spread_at_m, r.spread_normal,
                                                  r.spread_radius_m, spread_triangles_,
                                                  spread_load_, &spread_gradient_)) {
      continue;
    }
    if (load->nodes != r.nodes) continue;
    bool same = true;  // the row's own load (not moved by the column worker's fallback)
    for (int k = 0; k < r.nodes && same; ++k)
      same = load->slot[k] == r.slot[k] && load->weight[k] == r.w[k];
    if (!same) continue;
    for (int k = 0; k < r.nodes; ++k) weight_slide_[i][k] = r.point_slide.transpose() * (*dw)[k];
    weight_slides_[i] = 1;
    weights_move = true;
  }
  return weights_move;
}

// normal_turn, the sliding weights' terms on body b (slide_weights), summed node by node, not
// row pair by row pair (the same sums in another order: K as before up to round-off): U_k =
// -sum_s C_ks f_s over the body's stored forces (f_s on the tissue, -sum_j lambda_j w_jq n_j:
// every active row of every tool on it; a relaxing body's creep-equivalent forces, its
// history's with them) and Y_k (turn_y_), then per row i:
// sum_k (n_i . U_k) dw_ik (i sliding) + w_ik Y_k^T n_i, into turn_v_.
void State::slide_rows(int t, int ns, int b) {
  const int nc = static_cast<int>(rows_.size());
  turn_nodes_.clear();
  std::vector<int>& index = turn_node_[b];
  for (int i = 0; i < nc; ++i) {
    const Row& ri = rows_[i];
    if (ri.tool != t || ri.body != b || !(lambda_[ns + i] > 0.0)) continue;
    for (int k = 0; k < ri.nodes; ++k) {
      if (ri.slot[k] < 0 || ri.w[k] == 0.0) continue;
      int& at = index[ri.slot[k]];
      if (at < 0) {
        at = static_cast<int>(turn_nodes_.size());
        turn_nodes_.push_back(ri.slot[k]);
        turn_u_[at].setZero();
        turn_needs_u_[at] = 0;
        turn_y_[at].setZero();
      }
      if (weight_slides_[i]) turn_needs_u_[at] = 1;
    }
  }
  if (turn_nodes_.empty()) return;
  const int nk = static_cast<int>(turn_nodes_.size());
  const BodyState& bs = bodies_[b];
  list_u_nodes();
  bool compact = loaded_indices(b);
  if (!relaxing_displacement(b) && !bs.force_slots.empty()) node_displacements(b, compact);
  // Y_k: the sliding rows' terms (their column, normal and lambda_j dw_jq, in row and node
  // order) listed once, then node by node (each sum in the same order as term by term).
  slide_terms_.clear();
  for (int j = 0; j < nc; ++j) {
    const Row& rj = rows_[j];
    if (!weight_slides_[j] || rj.body != b) continue;
    const double lj = lambda_[ns + j];
    for (int q = 0; q < rj.nodes; ++q) {
      if (rj.slot[q] < 0 || rj.w[q] == 0.0) continue;
      const int at = compact ? loaded_blocks_[b].index(rj.slot[q]) : -1;
      if (at < 0) compact = false;  // (a node the copy has no room for: the columns then)
      slide_terms_.push_back({bs.columns->block(0, rj.slot[q]).data(), at, &rj.normal,
                              lj * weight_slide_[j][q]});
    }
  }
  slide_node_sums(b, compact);
  const double coupling = turn_coupling(b);  // a relaxing body's W at its alpha (turn_coupling)
  if (coupling != 1.0)
    for (int a = 0; a < nk; ++a) turn_y_[a] *= coupling;
  for (int i = 0; i < nc; ++i) {
    const Row& ri = rows_[i];
    if (ri.tool != t || ri.body != b || !(lambda_[ns + i] > 0.0)) continue;
    Vec3 v = Vec3::Zero();
    for (int k = 0; k < ri.nodes; ++k) {
      if (ri.slot[k] < 0 || ri.w[k] == 0.0) continue;
      const int a = index[ri.slot[k]];
      if (weight_slides_[i]) v.noalias() += ri.normal.dot(turn_u_[a]) * weight_slide_[i][k];
      v.noalias() += ri.w[k] * (turn_y_[a].transpose() * ri.normal);
    }
    turn_v_[i] += v;
  }
  for (int slot : turn_nodes_) index[slot] = -1;
}

// normal_turn (turn_node_sums, slide_rows): the indices into turn_nodes_ of the nodes that need
// U_k (turn_needs_u_), ascending, into turn_u_at_: listed once per node set, read by
// relaxing_displacement, node_displacements and turn_node_sums' Y_q.
void State::list_u_nodes() {
  const int nk = static_cast<int>(turn_nodes_.size());
  turn_u_at_.clear();
  for (int k = 0; k < nk; ++k)
    if (turn_needs_u_[k]) turn_u_at_.push_back(k);
}

// slide_rows' Y_k = sum over the sliding rows' terms (slide_terms_) of (C_kq n_j) (lambda_j
// dw_jq)^T, node by node (each sum in the same order as term by term), the blocks from the
// body's LoadedBlocks (compact: every term's node and turn_nodes_ there) else from the columns.
void State::slide_node_sums(int b, bool compact) {
  const ContactColumns& cols = *bodies_[b].columns;
  LoadedBlocks& loaded = loaded_blocks_[b];
  using Block = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>;
  const int nk = static_cast<int>(turn_nodes_.size());
  for (int a = 0; a < nk; ++a) {
    Mat3 y = turn_y_[a];
    if (compact) {
      const int i = loaded_node_index_[a];
      for (const SlideTerm& term : slide_terms_)
        y.noalias() += (Block(loaded.block(cols, i, term.index)) * *term.normal) * term.dw.transpose();
    } else {
      const std::ptrdiff_t at = 9 * static_cast<std::ptrdiff_t>(turn_nodes_[a]);
      for (const SlideTerm& term : slide_terms_)
        y.noalias() += (Block(term.column + at) * *term.normal) * term.dw.transpose();
    }
    turn_y_[a] = y;
  }
}

// normal_turn's U_k = -sum_s C_ks f_s (turn_rows, slide_rows) at the nodes of turn_u_at_
// (list_u_nodes; U_k zero on entry) on an elastic body with forces, unit m, once per node and
// step (turn_u_memo_): over the force slots in order (each sum as before), the sums held in
// registers, the blocks read from the body's LoadedBlocks (loaded_displacements; the loaded
// nodes' blocks kept across steps: loaded_indices), else from the columns.
void State::node_displacements(int b, bool compact) {
  std::vector<Vec3>& memo = turn_u_memo_[b];
  std::vector<std::uint64_t>& memo_stamp = turn_u_memo_stamp_[b];
  turn_u_todo_.clear();
  for (const int a : turn_u_at_) {
    const int slot = turn_nodes_[a];
    if (memo_stamp[slot] == turn_u_stamp_) {  // formed for another tool or phase this step
      turn_u_[a] = memo[slot];
    } else {
      turn_u_todo_.push_back(a);
    }
  }
  if (compact) {
    loaded_displacements(b);
  } else {
    column_displacements(b);
  }
  for (const int a : turn_u_todo_) {
    memo[turn_nodes_[a]] = turn_u_[a];
    memo_stamp[turn_nodes_[a]] = turn_u_stamp_;
  }
}

// node_displacements from the body's LoadedBlocks, at the nodes of turn_u_todo_: four nodes at a
// time over the force slots (four sums in flight: one node's sum waited on each subtraction's
// latency), each sum as before.
void State::loaded_displacements(int b) {
  const BodyState& bs = bodies_[b];
  const ContactColumns& cols = *bs.columns;
  LoadedBlocks& loaded = loaded_blocks_[b];
  const std::size_t nf = bs.force_slots.size();
  using Block = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>;
  const std::size_t n = turn_u_todo_.size();
  std::size_t k = 0;
  for (; k + 4 <= n; k += 4) {
    const int* a = turn_u_todo_.data() + k;
    const int i0 = loaded_node_index_[a[0]], i1 = loaded_node_index_[a[1]],
              i2 = loaded_node_index_[a[2]], i3 = loaded_node_index_[a[3]];
    Vec3 u0 = turn_u_[a[0]], u1 = turn_u_[a[1]], u2 = turn_u_[a[2]], u3 = turn_u_[a[3]];
    for (std::size_t f = 0; f < nf; ++f) {
      const int j = loaded_force_index_[f];
      const Vec3& force = bs.forces_n[f];
      u0.noalias() -= Block(loaded.block(cols, i0, j)) * force;
      u1.noalias() -= Block(loaded.block(cols, i1, j)) * force;
      u2.noalias() -= Block(loaded.block(cols, i2, j)) * force;
      u3.noalias() -= Block(loaded.block(cols, i3, j)) * force;
    }
    turn_u_[a[0]] = u0;
    turn_u_[a[1]] = u1;
    turn_u_[a[2]] = u2;
    turn_u_[a[3]] = u3;
  }
  for (; k < n; ++k) {
    const int a = turn_u_todo_[k];
    const int i = loaded_node_index_[a];
    Vec3 u = turn_u_[a];
    for (std::size_t f = 0; f < nf; ++f)
      u.noalias() -= Block(loaded.block(cols, i, loaded_force_index_[f])) * bs.forces_n[f];
    turn_u_[a] = u;
  }
}

// node_displacements from the columns (the nodes do not fit in the LoadedBlocks), at the nodes
// of turn_u_todo_: node by node, the node's blocks a few slots ahead fetched (each block is a
// cache miss: the loads of one block after another waited on memory).
void State::column_displacements(int b) {
  const BodyState& bs = bodies_[b];
  const ContactColumns& cols = *bs.columns;
  const std::size_t nf = bs.force_slots.size();
  using Block = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>;
  constexpr std::size_t kAhead = 6;
  for (const int a : turn_u_todo_) {
    const std::ptrdiff_t at = 9 * static_cast<std::ptrdiff_t>(turn_nodes_[a]);
    for (std::size_t f = 0; f < std::min(nf, kAhead); ++f) {
      const double* ahead = cols.block(0, bs.force_slots[f]).data() + at;
      __builtin_prefetch(ahead);
      __builtin_prefetch(ahead + 8);
    }
    Vec3 u = turn_u_[a];
    for (std::size_t f = 0; f < nf; ++f) {
      if (f + kAhead < nf) {
        const double* ahead = cols.block(0, bs.force_slots[f + kAhead]).data() + at;
        __builtin_prefetch(ahead);
        __builtin_prefetch(ahead + 8);
      }
      u.noalias() -= Block(cols.block(0, bs.force_slots[f]).data() + at) * bs.forces_n[f];
    }
    turn_u_[a] = u;
  }
}

// normal_turn's node sums on body b (turn_node_sums, slide_rows): the indices in the body's
// LoadedBlocks per force slot (loaded_force_index_) and per node of turn_nodes_
// (loaded_node_index_). When they do not fit beside the nodes held from earlier steps, the copy
// starts over; false if they do not fit at all (the sums read the columns).
bool State::loaded_indices(int b) {
  LoadedBlocks& loaded = loaded_blocks_[b];
  const BodyState& bs = bodies_[b];
  loaded.refresh(*bs.columns);
  for (int round = 0; round < 2; ++round) {
    bool fits = true;
    loaded_force_index_.clear();
    for (std::size_t f = 0; f < bs.force_slots.size() && fits; ++f) {
      const int i = loaded.index(bs.force_slots[f]);
      fits = i >= 0;
      loaded_force_index_.push_back(i);
    }
    for (std::size_t a = 0; a < turn_nodes_.size() && fits; ++a) {
      const int i = loaded.index(turn_nodes_[a]);
      fits = i >= 0;
      loaded_node_index_[a] = i;
    }
    if (fits) return true;
    loaded.clear();
  }
  return false;
}

// normal_turn, the last term: -N^T W^-1 V over tool t's active rows (V: turn_v_), added to K.
// One tool: the LCP's active inverse; several: own_stiffness's factor of this answer.
void State::turn_stiffness(int t, int ns, int tools, ToolContact& c) {
  Mat3 extra = Mat3::Zero();
  if (tools == 1) {
    extra = lcp_.contact_stiffness(
        ns,
        [&](int row) -> const Vec3* {
          const Row& q = rows_[row - ns];
          return q.tool == t ? &q.normal : nullptr;
        },
        [&](int row) -> const Vec3* {
          const Row& q = rows_[row - ns];
          return q.tool == t ? &turn_v_[row - ns] : nullptr;
        });
  } else {
    // own_stiffness's factor of this answer (K = -Y^T Y, L Y = N): -Y^T Z with L Z = V.
    const int n = static_cast<int>(own_rows_.size());
    if (n == 0 || c.stiffness_n_per_m.isZero(0.0)) return;
    for (int i = 0; i < n; ++i) {
      Vec3 z = turn_v_[own_rows_[i]];
      for (int q = 0; q < i; ++q) z -= own_factor_(i, q) * turn_z_.row(q).transpose();
      turn_z_.row(i) = (z / own_factor_(i, i)).transpose();
      extra.noalias() -= own_y_.row(i).transpose() * turn_z_.row(i);
    }
  }
  if (turn_scale_ != 1.0) extra *= turn_scale_;  // relaxation's alpha (turn_coupling)
  c.stiffness_n_per_m += extra;
}

// Phase "tier post": the tier's equilibrium follows these forces (worker thread; or now,
// deterministic).
void State::tier_post(StepStats& stats) {
  if (!tier_) return;
  for (std::size_t bi = 0; bi < bodies_.size(); ++bi) {
    tier_loads_[bi].slots = bodies_[bi].force_slots;
    tier_loads_[bi].forces_n = bodies_[bi].forces_n;
    tier_loads_[bi].linearization = tier_->linearization(static_cast<int>(bi)).count;
    tier_loads_[bi].time_s = step_time_s_;  // a relaxing body's equilibrium moves in time
  }
  const auto u0 = Clock::now();
  stats.tier_updated = tier_->post(tier_loads_);
  if (stats.tier_updated) {
    stats.tier_update_us = std::chrono::duration<double, std::micro>(Clock::now() - u0).count();
    count_tier_elements(*tier_, bodies_.size(), stats);  // of the equilibrium just made
  }
}

// Phases "rows" to "LCP" on the current geometry: the rows of every tool, their compliance
// columns, W and delta, the LCP (warm start: the sliding rows active in the last good step, the
// contact rows that penetrate; the sliding block of W never changes, so its active or inactive
// set and factor carry over, and with sliding_inactive_set its inverse was computed at load).
LcpResult State::solve_geometry(const Model& m, const std::vector<ToolPose>& poses,
                                StepStats& stats) {
  ++geometry_counter_;
  rows_.clear();
  row_main_slot_.clear();
  geometry_rows_dropped_ = 0;
  spread_prev_memo_.swap(spread_memo_);
  spread_memo_.clear();
  spread_prev_keys_.swap(spread_keys_);
  spread_keys_.clear();
  // The rest surface: LINEAR (no tier offsets in the rows) with no force on any body.
  rest_geometry_ = !tier_;
  for (const BodyState& bs : bodies_)
    if (!bs.force_slots.empty() || bs.max_displacement_m != 0.0) rest_geometry_ = false;
  if (!m.tools_.empty()) {
    for (int t = 0; t < static_cast<int>(poses.size()); ++t)
      rows_of_tool(m, t, poses[t], poses[t].axis.normalized());
  }
  const int nc = static_cast<int>(rows_.size());
  const int ns = m.num_sliding_;  // sliding rows first (constant block of W), then contact rows
  compliance_columns(stats);
  delassus(m, ns);
  near_field(ns);
  for (int k = 0; k < ns; ++k) warm_[k] = sliding_active_[k];
  for (int r = 0; r < nc; ++r) warm_[ns + r] = delta_[ns + r] > 0.0 ? 1 : 0;
  LcpOptions lcp_options;
  lcp_options.tolerance = m.options_.lcp_tolerance;
  lcp_options.max_iterations =
      m.options_.lcp_max_iterations + m.options_.lcp_iterations_per_sliding_row * ns;
  lcp_options.path = !m.options_.sliding_inactive_set        ? LcpPath::reference
                     : m.options_.sliding_inactive_set_always ? LcpPath::inactive_set
                                                              : LcpPath::automatic;
  LcpProblem problem{&w_, &delta_, ns + nc, ns, &warm_};
  if (ns > 0) {
    problem.column_terms = &column_terms_;
    problem.terms_per_row = kSpreadNodes;
  }
  // The warm start (no sliding rows): the rows active in the last converged LCP, by key. Only
  // the pivots depend on it, not the answer (SimulationOptions::lcp_warm_start).
  const bool warm = m.options_.lcp_warm_start && ns == 0;
  if (warm) {
    for (int r = 0; r < nc; ++r)
      warm_active_[r] =
          std::binary_search(active_keys_.begin(), active_keys_.end(), row_key(rows_[r])) ? 1 : 0;
    problem.warm_active = &warm_active_;
  }
  const LcpResult result = lcp_.solve(problem, lcp_options, lambda_);
  if (warm && result.converged) {
    active_keys_.clear();
    for (int r = 0; r < nc; ++r)
      if (lambda_[r] > 0.0) active_keys_.push_back(row_key(rows_[r]));
    std::sort(active_keys_.begin(), active_keys_.end());
  }
  return result;
}

// The last good forces of every body, kept while the step iterates (no allocation: reserved).
void State::save_forces() {
  for (std::size_t bi = 0; bi < bodies_.size(); ++bi) {
    const BodyState& bs = bodies_[bi];
    ForceBackup& k = backup_[bi];
    k.slots = bs.force_slots;
    k.forces_n = bs.forces_n;
    k.sliding_lambda = bs.sliding_lambda;
    k.max_displacement_m = bs.max_displacement_m;
  }
  sliding_active_backup_ = sliding_active_;
}

void State::restore_forces(bool to_rest) {
  for (std::size_t bi = 0; bi < bodies_.size(); ++bi) {
    BodyState& bs = bodies_[bi];
    for (int s : bs.force_slots) bs.force_index[s] = -1;
    bs.force_slots.clear();
    bs.forces_n.clear();
    bs.max_displacement_m = 0.0;
    // From rest, as an elastic body: a viscoelastic body's history enters the first LCP (its
    // depths and forces) but not the first rows, so a held history gives the elastic rows.
    if (to_rest) continue;
    const ForceBackup& k = backup_[bi];
    bs.force_slots = k.slots;
    bs.forces_n = k.forces_n;
    bs.sliding_lambda = k.sliding_lambda;
    bs.max_displacement_m = k.max_displacement_m;
    for (std::size_t i = 0; i < bs.force_slots.size(); ++i)
      bs.force_index[bs.force_slots[i]] = static_cast<int>(i);
  }
  if (!to_rest) sliding_active_ = sliding_active_backup_;
}

// The rows of this geometry as sorted (tool, feature) keys; true if they equal the last ones.
bool State::same_rows_as_before() {
  row_keys_.clear();
  for (const Row& r : rows_) row_keys_.push_back(row_key(r));
  std::sort(row_keys_.begin(), row_keys_.end());
  const bool same = row_keys_ == previous_row_keys_;
  previous_row_keys_.swap(row_keys_);
  return same;
}

// LINEAR: the rows are found on the rest surface (contact_geometry_iterations = 1, the default),
// as in the multirate tiers: the answer is a function of the poses alone (a replay equals the
// live run; a held pose gives the same force at every step). With more iterations the rows
// follow the surface deformed by this step's own answer (rows, LCP, rows on that surface, ...)
// until they are the same features twice: kept for comparison. Measured on the cube's 25 mm tip
// 8 mm deep: iterated, 6 of 6 geometries and 175-180 N depending on the pose by 1 mm; the rows
// found once per step on the last step's surface (SOFA's way) give a held pose a force
// alternating 167-180 N and a lateral force changing sign from step to step (a vibration the
// hand would feel); the rest surface, 152 N at every step, one LCP.
void State::step(const Model& m, const std::vector<ToolPose>& poses, double time_s,
                 std::vector<ToolContact>& contacts, StepStats& stats) {
  const auto t0 = Clock::now();
  check_poses(m, poses);
  try {
    hold_poses(m, poses);
    solve_held_poses(m, time_s, contacts, stats, t0);
  } catch (...) {
    // A step that fails changes no station's proxy (the service steps the others without it).
    restore_proxies();
    throw;
  }
}

// Phase "pose": with rigid obstacles, each station's tip held on the free side of the bone by its
// proxy (the god-object: the device's tip projected onto the planes around where the tip was last
// free), so the tissue behind the bone is never pushed through it; the rest of the step uses
// these poses. In the State, not in the service, so a replay holds the tool as the live server.
void State::hold_poses(const Model& m, const std::vector<ToolPose>& poses) {
  held_.assign(poses.begin(), poses.end());
  planes_.resize(poses.size());
  for (auto& p : planes_) p.count = 0;
  proxy_before_.clear();
  if (!m.rigid_) return;
  for (std::size_t t = 0; t < poses.size(); ++t) {
    const int key = poses[t].station >= 0 ? poses[t].station : static_cast<int>(t);
    // A station's first pose makes its proxy (allocation once per station).
    if (key >= static_cast<int>(proxies_.size())) proxies_.resize(static_cast<std::size_t>(key) + 1);
    auto& proxy = proxies_[static_cast<std::size_t>(key)];
    if (!proxy) proxy = std::make_unique<ToolProxy>(*m.rigid_, m.proxy_options_);
    proxy_before_.emplace_back(key, proxy->memory());
    proxy->constrain(m.tools_[static_cast<std::size_t>(held_[t].tool)], held_[t], planes_[t]);
  }
}

void State::restore_proxies() {
  for (auto it = proxy_before_.rbegin(); it != proxy_before_.rend(); ++it)
    proxies_[static_cast<std::size_t>(it->first)]->restore(it->second);
  proxy_before_.clear();
}

// Column worker with a bounded cache: before any column is read in this step, the slots the
// worker proposed for eviction are given up unless this State holds them (a force slot of the
// last answer, which the step's positions and its restore read without has(), or a relaxing
// body's history slot); contact_columns.hpp.
void State::grant_evictions() {
  for (BodyState& bs : bodies_) {
    bs.columns->grant_eviction([&bs](int s) {
      return bs.force_index[s] >= 0 || (bs.history && bs.history->holds(s));
    });
  }
}

// The held poses through candidates, rows, columns, Delassus, LCP, answer and tier post.
void State::solve_held_poses(const Model& m, double time_s, std::vector<ToolContact>& contacts,
                             StepStats& stats, std::chrono::steady_clock::time_point t0) {
  const std::vector<ToolPose>& poses = held_;
  const int nt = static_cast<int>(poses.size());
  if (column_worker_) {
    column_worker_->post(poses);  // look ahead of the held poses (never waits)
    grant_evictions();
  }
  begin_step(m, nt, stats);
  begin_history(m, time_s);
  if (static_cast<int>(contacts.size()) != nt) contacts.resize(nt);
  // Each answer lists up to three nodes per row: room for all of them once, not per step.
  for (auto& c : contacts)
    if (c.nodes.capacity() < static_cast<std::size_t>(3 * m.options_.max_contact_nodes_per_tool))
      c.nodes.reserve(3 * m.options_.max_contact_nodes_per_tool);
  const int ns = m.num_sliding_;
  const bool iterate = !tier_;
  save_forces();
  if (iterate) restore_forces(true);  // from rest
  previous_row_keys_.clear();
  stats.columns_computed = 0;
  stats.columns_not_ready = 0;
  stats.geometry_iterations = 0;
  stats.lcp_pivots = 0;
  stats.lcp_warm_taken = 0;
  LcpResult lcp;
  int columns = 0, not_ready = 0;
  for (int it = 0;; ++it) {
    lcp = solve_geometry(m, poses, stats);
    stats.lcp_pivots += lcp.iterations;
    stats.lcp_warm_taken += lcp.warm_taken ? 1 : 0;
    columns += stats.columns_computed;
    not_ready = std::max(not_ready, stats.columns_not_ready);
    ++stats.geometry_iterations;
    if (!lcp.converged) break;
    for (int k = 0; k < ns; ++k) sliding_active_[k] = lambda_[k] > 0.0 ? 1 : 0;
    store_forces(m, ns);
    if (!iterate || rows_.empty() || same_rows_as_before() ||
        it + 1 >= m.options_.contact_geometry_iterations) {
      if (!iterate) largest_displacement(m);
      break;
    }
    largest_displacement(m);
  }
  stats.columns_computed = columns;
  stats.columns_not_ready = not_ready;  // the most of one geometry (the same nodes recur)
  columns_not_ready_ += static_cast<std::uint64_t>(not_ready);
  stats.contact_rows = static_cast<int>(rows_.size());
  stats.candidate_tests = candidate_tests_;
  stats.contact_rows_dropped = geometry_rows_dropped_;  // of the geometry answered
  if (geometry_rows_dropped_ > 0) ++steps_with_rows_dropped_;
  stats.sliding_rows = ns;
  stats.converged = lcp.converged;
  if (!lcp.converged) {
    // Keep the last good answer (contact and sliding forces), say that this step did not
    // converge.
    ++steps_not_converged_;
    restore_forces(false);
    for (int t = 0; t < nt; ++t) {
      contacts[t] = last_good_[t];
      contacts[t].converged = false;
      contacts[t].iterations = lcp.iterations;
      contacts[t].rigid_planes = planes_[t];
      contacts[t].held_tip_m = poses[t].tip_m;
    }
    stats.solve_us = std::chrono::duration<double, std::micro>(Clock::now() - t0).count();
    return;
  }
  stats.sliding_active = 0;
  for (int k = 0; k < ns; ++k) stats.sliding_active += sliding_active_[k];
  for (int t = 0; t < nt; ++t) {
    answer(m, t, poses[t], ns, lcp.iterations, nt, contacts[t]);
    contacts[t].rigid_planes = planes_[t];
    contacts[t].held_tip_m = poses[t].tip_m;
  }
  commit_history();
  ++turn_u_stamp_;  // the forces node_displacements sums are these until the next step
  for (int t = 0; t < nt; ++t) {
    relaxation(m, t, ns, contacts[t]);
    normal_turn(m, t, ns, nt, contacts[t]);
    last_good_[t] = contacts[t];
  }
  tier_post(stats);
  stats.solve_us = std::chrono::duration<double, std::micro>(Clock::now() - t0).count();
}

// Phase "history" (viscoelastic bodies only): the step's time since the last converged one,
// alpha and the history forces of each relaxing body (viscoelastic_history.hpp).
void State::begin_history(const Model& m, double time_s) {
  step_time_s_ = time_s;
  if (!m.viscoelastic_ && !relaxing_near_field_) return;
  if (!std::isfinite(time_s))
    throw std::invalid_argument("Simulation::step: the step's time is not finite");
  step_time_s_ = timed_ ? std::max(time_s, time_s_) : time_s;
  const double dt = timed_ ? step_time_s_ - time_s_ : 0.0;
  for (auto& bs : bodies_) {
    if (bs.history) bs.history->begin(dt);
    if (bs.near_field_history) bs.near_field_history->begin(dt);
  }
}

// The step converged: its forces enter the history, its time is the last one.
void State::commit_history() {
  time_s_ = step_time_s_;
  timed_ = true;
  for (auto& bs : bodies_) {
    if (bs.history) bs.history->commit(bs.force_slots, bs.forces_n);
    if (bs.near_field_history)
      bs.near_field_history->commit(bs.near_field_tools, bs.near_field_forces_n);
  }
}

// The history forces of a body as its first loaded slots (store_forces adds the rows' onto them).
void State::add_history_forces(BodyState& bs) {
  const auto& slots = bs.history->slots();
  const auto& h = bs.history->forces_n();
  for (std::size_t i = 0; i < slots.size(); ++i) {
    bs.force_index[slots[i]] = static_cast<int>(bs.force_slots.size());
    bs.force_slots.push_back(slots[i]);
    bs.forces_n.push_back(h[i]);
    bs.history_forces_n[i] = h[i];  // (the step's history: commit_history replaces it)
  }
  bs.history_count = static_cast<int>(slots.size());
}

}  // namespace neurosim::interaction
