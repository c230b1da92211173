// CoupledBody: host factor, boundary operator (Woodbury), coupled solves (see the header).
#include "server/interaction/coupled_body.hpp"

#include "common/clock.hpp"

#include <Eigen/Cholesky>
#include <Eigen/SparseCore>

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <utility>

namespace neurosim::interaction {

namespace {

using common::seconds_since;

// X = L B for free-dof right-hand sides b of a host with ties: Woodbury on the tie stiffness,
// L b = L_A (b - P_b^T G (L_A b)[b]), two host solves; apply(v, gv) gives gv = G v (m3 rows, the
// boundary dofs boundary_nodes (A ids) in triples).
template <typename Solve, typename Apply>
void woodbury_solve(const std::vector<int>& reduced, const std::vector<int>& boundary_nodes,
                    int m3, const Solve& solve, const Apply& apply, const Eigen::MatrixXd& b,
                    Eigen::MatrixXd& x) {
  solve(b, x);
  if (m3 == 0) return;
  Eigen::MatrixXd v = Eigen::MatrixXd::Zero(m3, b.cols()), gv;
  for (int r = 0; r < m3; ++r) {
    const int red = reduced[3 * boundary_nodes[r / 3] + r % 3];
    if (red >= 0) v.row(r) = x.row(red);
  }
  apply(v, gv);
  Eigen::MatrixXd rhs = b;
  for (int r = 0; r < m3; ++r) {
    const int red = reduced[3 * boundary_nodes[r / 3] + r % 3];
    if (red >= 0) rhs.row(red) -= gv.row(r);
  }
  solve(rhs, x);
}

// One exposed part of the contact mesh (a tied or a sliding embedded mesh): slot s beyond the
// host's belongs to it when owner[s - first_slot] == part; its node is nodes[s] - offset.
struct ExposedPart {
  const std::vector<int>& nodes;
  int first_slot;
  const std::vector<int>& owner;
  int part;
  int offset;
  int num_vertices;
};

// The forces (3 num_vertices, unit N) the slots of `part` put on its own nodes; false if none.
// Throws on a non-finite force.
bool part_contact_forces(const ExposedPart& part, const std::vector<int>& slots,
                         const std::vector<mesh::Vec3>& forces_n, Eigen::VectorXd& forces_b) {
  bool any = false;
  forces_b.setZero(3 * static_cast<Eigen::Index>(part.num_vertices));
  for (std::size_t k = 0; k < slots.size() && k < forces_n.size(); ++k) {
    const int s = slots[k];
    if (s < part.first_slot || s >= static_cast<int>(part.nodes.size()) ||
        part.owner[static_cast<std::size_t>(s - part.first_slot)] != part.part)
      continue;
    if (!forces_n[k].allFinite())
      throw std::invalid_argument("CoupledBody: contact force at entry " + std::to_string(k) +
                                  " (slot " + std::to_string(s) + ") is not finite");
    forces_b.segment<3>(3 * (part.nodes[static_cast<std::size_t>(s)] - part.offset)) +=
        forces_n[k];
    any = true;
  }
  return any;
}

}  // namespace

std::vector<mesh::Vec3> surface_vertex_normals(const mesh::TetMesh& m) {
  std::vector<mesh::Vec3> normals(m.num_vertices(), mesh::Vec3::Zero());
  const auto& x = m.vertices();
  for (const auto& t : m.surface()) {
    const mesh::Vec3 n = (x[t[1]] - x[t[0]]).cross(x[t[2]] - x[t[0]]);  // 2 area * unit normal
    for (int v : t) normals[v] += n;
  }
  for (auto& n : normals) {
    const double len = n.norm();
    if (len > 0.0) n /= len;
  }
  return normals;
}

CoupledBody::CoupledBody(int host_index, const mesh::TetMesh& host, const fem::Material& material,
                         const std::vector<int>& host_fixed,
                         const fem::SolverOptions& solver_options)
    : host_index_(host_index), host_(&host), material_(material) {
  const auto t0 = std::chrono::steady_clock::now();
  solver_ = std::make_unique<fem::StaticSolver>(host, fem::MaterialMap::uniform(material),
                                                host_fixed, solver_options);
  timing_.factor_s = seconds_since(t0);
  boundary_slot_.assign(host.num_vertices(), -1);
  contact_slot_.assign(host.num_vertices(), -1);
}

int CoupledBody::add_sliding_rows(const std::vector<HostSlidingRow>& rows,
                                  const std::string& what) {
  if (finalized_) throw std::logic_error("CoupledBody::add_sliding_rows after finalize");
  check_sliding_rows(rows, static_cast<int>(host_->num_vertices()), what);
  const int first = static_cast<int>(sliding_rows_.size());
  for (const auto& r : rows) sliding_rows_.push_back(r);
  return first;
}

void CoupledBody::cover_faces(const std::vector<mesh::Tri>& faces) {
  if (finalized_) throw std::logic_error("CoupledBody::cover_faces after finalize");
  const int n = static_cast<int>(host_->num_vertices());
  for (const auto& t : faces) {
    std::array<int, 3> f{t[0], t[1], t[2]};
    for (int v : f)
      if (v < 0 || v >= n)
        throw std::invalid_argument("CoupledBody::cover_faces: host node " + std::to_string(v) +
                                    " out of range");
    std::sort(f.begin(), f.end());
    covered_faces_.push_back(f);
  }
}

void CoupledBody::expose_tie(int tie, const std::vector<char>& outside) {
  if (finalized_) throw std::logic_error("CoupledBody::expose_tie after finalize");
  if (tie < 0 || tie >= static_cast<int>(ties_.size()))
    throw std::invalid_argument("CoupledBody::expose_tie: no tie " + std::to_string(tie));
  if (outside.size() != ties_[tie].geometry().num_vertices())
    throw std::invalid_argument("CoupledBody::expose_tie: " + std::to_string(outside.size()) +
                                " flags for " +
                                std::to_string(ties_[tie].geometry().num_vertices()) + " nodes");
  exposed_.resize(ties_.size());
  exposed_[tie] = outside;
}

void CoupledBody::expose_slide(int slide, const SlidingCoupling& coupling, int first_row,
                               const std::vector<char>& outside) {
  if (finalized_) throw std::logic_error("CoupledBody::expose_slide after finalize");
  if (slide < 0 || first_row < 0 ||
      first_row + coupling.size() > static_cast<int>(sliding_rows_.size()))
    throw std::invalid_argument("CoupledBody::expose_slide: slide " + std::to_string(slide) +
                                " with rows from " + std::to_string(first_row) +
                                " is not among the body's sliding rows");
  if (outside.size() != coupling.geometry().num_vertices())
    throw std::invalid_argument("CoupledBody::expose_slide: " + std::to_string(outside.size()) +
                                " flags for " + std::to_string(coupling.geometry().num_vertices()) +
                                " nodes");
  if (static_cast<std::size_t>(slide) >= exposed_slides_.size())
    exposed_slides_.resize(static_cast<std::size_t>(slide) + 1);
  exposed_slides_[slide] = ExposedSlide{&coupling, first_row, outside, -1};
}

int CoupledBody::part_mesh(int part) const {
  if (part < 0) return host_index_;
  if (part < static_cast<int>(ties_.size())) return ties_[part].mesh();
  const SlidingCoupling* sl = exposed_slide(part - static_cast<int>(ties_.size()));
  if (sl == nullptr)
    throw std::invalid_argument("CoupledBody::part_mesh: no part " + std::to_string(part));
  return sl->mesh();
}

void CoupledBody::select_exposed_contact_nodes() {
  std::vector<mesh::Vec3> vertices = host_->vertices();
  std::vector<mesh::Tet> tets = host_->tets();
  tie_offset_.assign(ties_.size(), -1);
  // The exposed meshes: the ties first, then the sliding meshes (their slots in that order).
  struct Exposed {
    const mesh::TetMesh* geometry;
    const std::vector<char>* outside;
    const std::vector<int>* fixed;
    int tie, slide;
  };
  std::vector<Exposed> parts;
  for (std::size_t t = 0; t < ties_.size(); ++t) {
    if (t >= exposed_.size() || exposed_[t].empty()) continue;
    parts.push_back(
        {&ties_[t].geometry(), &exposed_[t], &ties_[t].fixed_nodes(), static_cast<int>(t), -1});
  }
  for (std::size_t i = 0; i < exposed_slides_.size(); ++i) {
    const ExposedSlide& e = exposed_slides_[i];
    if (e.coupling == nullptr) continue;
    parts.push_back(
        {&e.coupling->geometry(), &e.outside, &e.coupling->fixed_nodes(), -1, static_cast<int>(i)});
  }
  for (const Exposed& part : parts) {
    const auto& b = *part.geometry;
    const int offset = static_cast<int>(vertices.size());
    (part.tie >= 0 ? tie_offset_[part.tie] : exposed_slides_[part.slide].offset) = offset;
    vertices.insert(vertices.end(), b.vertices().begin(), b.vertices().end());
    for (const auto& tet : b.tets())
      tets.push_back({tet[0] + offset, tet[1] + offset, tet[2] + offset, tet[3] + offset});
  }
  mesh::BuildOptions bo;
  bo.drop_unused_vertices = false;
  bo.source = host_->source() + " (with the exposed embedded meshes, contact geometry)";
  contact_mesh_ = std::make_unique<mesh::TetMesh>(mesh::TetMesh::build(vertices, tets, bo));
  contact_slot_.resize(vertices.size(), -1);
  contact_excluded_faces_ = covered_faces_;
  for (const Exposed& part : parts) {
    const auto& b = *part.geometry;
    const auto& out = *part.outside;
    const int offset = part.tie >= 0 ? tie_offset_[part.tie] : exposed_slides_[part.slide].offset;
    // Faces with a node outside A are contactable (a face across the rim too: no gap between
    // A's ring and B's exposed part); those wholly inside are under A, never touched.
    std::vector<mesh::Vec3> normals(b.num_vertices(), mesh::Vec3::Zero());
    const auto& x = b.vertices();
    for (const auto& f : b.surface()) {
      if (!out[f[0]] && !out[f[1]] && !out[f[2]]) {
        std::array<int, 3> e{f[0] + offset, f[1] + offset, f[2] + offset};
        std::sort(e.begin(), e.end());
        contact_excluded_faces_.push_back(e);
        continue;
      }
      const mesh::Vec3 n = (x[f[1]] - x[f[0]]).cross(x[f[2]] - x[f[0]]);
      for (int v : f) normals[v] += n;
    }
    const auto& fixed = *part.fixed;
    for (int v : b.surface_vertices()) {
      if (std::binary_search(fixed.begin(), fixed.end(), v)) {
        contact_fixed_nodes_.push_back(v + offset);
        continue;
      }
      const double len = normals[v].norm();
      if (len == 0.0) continue;
      contact_slot_[v + offset] = static_cast<int>(contact_nodes_.size());
      contact_nodes_.push_back(v + offset);
      contact_normals_.push_back(normals[v] / len);
      contact_tie_.push_back(part.tie);
      contact_slide_.push_back(part.slide);
      exposed_slide_slots_ = exposed_slide_slots_ || part.slide >= 0;
    }
  }
  std::sort(contact_excluded_faces_.begin(), contact_excluded_faces_.end());
  std::sort(contact_fixed_nodes_.begin(), contact_fixed_nodes_.end());
}

void CoupledBody::select_contact_nodes() {
  std::sort(covered_faces_.begin(), covered_faces_.end());
  covered_faces_.erase(std::unique(covered_faces_.begin(), covered_faces_.end()),
                       covered_faces_.end());
  // Area-weighted normals over the uncovered surface faces: a node at the rim of a covered
  // groove points out of the host's surface, not into the embedded mesh.
  std::vector<mesh::Vec3> normals(host_->num_vertices(), mesh::Vec3::Zero());
  const auto& x = host_->vertices();
  for (const auto& t : host_->surface()) {
    std::array<int, 3> f{t[0], t[1], t[2]};
    std::sort(f.begin(), f.end());
    if (std::binary_search(covered_faces_.begin(), covered_faces_.end(), f)) continue;
    const mesh::Vec3 n = (x[t[1]] - x[t[0]]).cross(x[t[2]] - x[t[0]]);  // 2 area * unit normal
    for (int v : t) normals[v] += n;
  }
  for (auto& n : normals) {
    const double len = n.norm();
    if (len > 0.0) n /= len;
  }
  // Fixed nodes cannot move (a row there could never be satisfied); a node only on covered faces
  // (zero normal) is under the embedded mesh: neither is contactable.
  for (int v : host_->surface_vertices()) {
    if (solver_->is_fixed_node(v) || normals[v].squaredNorm() == 0.0) continue;
    contact_slot_[v] = static_cast<int>(contact_nodes_.size());
    contact_nodes_.push_back(v);
    contact_normals_.push_back(normals[v]);
  }
  num_host_contact_ = static_cast<int>(contact_nodes_.size());
  contact_fixed_nodes_ = solver_->fixed_nodes();
  std::sort(contact_fixed_nodes_.begin(), contact_fixed_nodes_.end());
  bool exposed = false;
  for (const auto& e : exposed_) exposed = exposed || !e.empty();
  for (const auto& e : exposed_slides_) exposed = exposed || e.coupling != nullptr;
  if (exposed) select_exposed_contact_nodes();
}

void CoupledBody::add_tie(const TieDefinition& def) {
  if (finalized_) throw std::logic_error("CoupledBody::add_tie after finalize");
  const auto t0 = std::chrono::steady_clock::now();
  ties_.emplace_back(def, static_cast<int>(host_->num_vertices()));
  timing_.condense_s += seconds_since(t0);
}

void CoupledBody::finalize() {
  if (finalized_) return;
  finalized_ = true;
  auto t0 = std::chrono::steady_clock::now();
  for (const auto& tie : ties_)
    for (const auto& tri : tie.host_nodes())
      boundary_nodes_.insert(boundary_nodes_.end(), tri.begin(), tri.end());
  std::sort(boundary_nodes_.begin(), boundary_nodes_.end());
  boundary_nodes_.erase(std::unique(boundary_nodes_.begin(), boundary_nodes_.end()),
                        boundary_nodes_.end());
  for (std::size_t s = 0; s < boundary_nodes_.size(); ++s)
    boundary_slot_[boundary_nodes_[s]] = static_cast<int>(s);
  select_contact_nodes();
  const int m3 = 3 * static_cast<int>(boundary_nodes_.size());
  if (m3 > 0) {
    std::string cache_file;
    if (!cache_dir_.empty()) {
      char name[64];
      std::snprintf(name, sizeof name, "coupling_%016llx.bin",
                    static_cast<unsigned long long>(cache_key()));
      cache_file = (std::filesystem::path(cache_dir_) / name).string();
      if (load_boundary_operator(cache_file, cache_key(), 3 * static_cast<int>(boundary_nodes_.size()),
                                 3 * num_host_contact_, op_)) {
        cache_hit_ = true;
        timing_.boundary_s = seconds_since(t0);
      }
    }
    if (!cache_hit_) {
      compute_boundary_operator();
      if (!cache_file.empty()) save_boundary_operator(cache_file, cache_key(), op_);
    }
  }
  // The baseline's operator (P = L_bb K_add, relaxation) at load, not on first use.
  if (iterative_requested_ && m3 > 0)
    iterative_ = std::make_unique<IterativeTie>(*this, iterative_options_);
  if (!sliding_rows_.empty()) {
    t0 = std::chrono::steady_clock::now();
    sliding_ = SlidingOperator(SlidingOperatorDefinition{
        std::move(sliding_rows_), solver_.get(),
        [this](const Eigen::MatrixXd& b, Eigen::MatrixXd& x) { coupled_solve_reduced(b, x); },
        kBlockColumns});
    sliding_rows_.clear();
    timing_.sliding_s = seconds_since(t0);
  }
}

void CoupledBody::coupled_solve_reduced(const Eigen::MatrixXd& b, Eigen::MatrixXd& x,
                                        fem::SolveWorkspace* ws,
                                        IterativeReport* iterations) const {
  const auto solve = [&](const Eigen::MatrixXd& rhs, Eigen::MatrixXd& out) {
    if (ws != nullptr) solver_->solve_reduced(rhs, out, *ws);
    else solver_->solve_reduced(rhs, out);
  };
  const auto apply = [&](const Eigen::MatrixXd& v, Eigen::MatrixXd& gv) {
    apply_coupling(v, gv, iterations);
  };
  woodbury_solve(solver_->reduced_index(), boundary_nodes_, static_cast<int>(op_.l_bb.rows()),
                 solve, apply, b, x);
}

void CoupledBody::coupled_displacement(const Eigen::MatrixXd& forces_n,
                                       Eigen::MatrixXd& u_host_m, fem::SolveWorkspace* ws) const {
  const int n3 = 3 * static_cast<int>(host_->num_vertices());
  if (forces_n.rows() != n3 || !forces_n.allFinite())
    throw std::invalid_argument("CoupledBody::coupled_displacement: bad force vector");
  const int nf = solver_->num_free_dofs();
  const auto& free = solver_->free_dofs();
  Eigen::MatrixXd rhs(nf, forces_n.cols()), x;
  for (int r = 0; r < nf; ++r) rhs.row(r) = forces_n.row(free[r]);
  coupled_solve_reduced(rhs, x, ws);
  u_host_m.setZero(n3, forces_n.cols());
  for (int r = 0; r < nf; ++r) u_host_m.row(free[r]) = x.row(r);
}

void CoupledBody::coupled_displacement(const Eigen::VectorXd& forces_n,
                                       Eigen::VectorXd& u_host_m, fem::SolveWorkspace* ws) const {
  Eigen::MatrixXd u;
  coupled_displacement(Eigen::MatrixXd(forces_n), u, ws);
  u_host_m = u.col(0);
}

void CoupledBody::tied_mesh_displacement(int tie, const Eigen::VectorXd& forces_n,
                                         Eigen::VectorXd& u_host_m,
                                         Eigen::VectorXd& u_embedded_m) const {
  if (tie < 0 || tie >= static_cast<int>(ties_.size()))
    throw std::invalid_argument("CoupledBody::tied_mesh_displacement: no tie " +
                                std::to_string(tie));
  Eigen::VectorXd load = Eigen::VectorXd::Zero(3 * static_cast<int>(host_->num_vertices()));
  ties_[tie].add_equivalent_host_load(forces_n, load);
  coupled_displacement(load, u_host_m);
  ties_[tie].displacement(u_host_m, forces_n, u_embedded_m);
}

void CoupledBody::compute_boundary_operator() {
  auto t0 = std::chrono::steady_clock::now();
  const int m3 = 3 * static_cast<int>(boundary_nodes_.size());
  const int s3 = 3 * num_host_contact_;  // A's contact slots (a tie's are solved per column)
  // Compliance columns of A at the boundary dofs (paper Eq. 5, L_bb and L_cb), by block solves.
  op_.l_bb.setZero(m3, m3);
  op_.l_sb.setZero(s3, m3);
  const auto& reduced = solver_->reduced_index();
  const int nf = solver_->num_free_dofs();
  std::vector<int> cols;
  for (int c = 0; c < m3; ++c)
    if (reduced[3 * boundary_nodes_[c / 3] + c % 3] >= 0)
      cols.push_back(c);  // fixed dofs: zero column
  Eigen::MatrixXd rhs, x;
  for (std::size_t first = 0; first < cols.size(); first += kBlockColumns) {
    const int n = static_cast<int>(std::min<std::size_t>(kBlockColumns, cols.size() - first));
    rhs.setZero(nf, n);
    for (int j = 0; j < n; ++j) {
      const int c = cols[first + j];
      rhs(reduced[3 * boundary_nodes_[c / 3] + c % 3], j) = 1.0;
    }
    solver_->solve_reduced(rhs, x);
    for (int j = 0; j < n; ++j) {
      const int c = cols[first + j];
      for (int r = 0; r < m3; ++r) {
        const int red = reduced[3 * boundary_nodes_[r / 3] + r % 3];
        if (red >= 0) op_.l_bb(r, c) = x(red, j);
      }
      for (int r = 0; r < s3; ++r) op_.l_sb(r, c) = x(reduced[3 * contact_nodes_[r / 3] + r % 3], j);
    }
  }
  op_.l_bb = (0.5 * (op_.l_bb + op_.l_bb.transpose())).eval();
  timing_.boundary_s = seconds_since(t0);

  // Coupling operator: K_add = sum J^T S_B J, G = (I + K_add L_bb)^-1 K_add, factored once.
  // Only G's block on the free boundary dofs is ever used (L_bb is zero at fixed ones), and
  // there G = K_add (S_A + K_add)^-1 S_A with S_A = L_bb^-1 (A condensed on the boundary):
  // symmetric positive (semi)definite factors only. The unsymmetric I + K_add L_bb has a
  // condition number of the order of the stiffness ratio times A's; its LU lost 4 digits of G at
  // artery/brain 1e6 (2e-4 error in the coupled field), the Cholesky form loses none of them
  // to the ratio.
  t0 = std::chrono::steady_clock::now();
  op_.k_add.setZero(m3, m3);
  for (const auto& tie : ties_) tie.add_stiffness(boundary_slot_, op_.k_add);
  op_.k_add = (0.5 * (op_.k_add + op_.k_add.transpose())).eval();
  std::vector<int> free_b;
  for (int c = 0; c < m3; ++c)
    if (reduced[3 * boundary_nodes_[c / 3] + c % 3] >= 0) free_b.push_back(c);
  const int nb = static_cast<int>(free_b.size());
  Eigen::MatrixXd l_ff(nb, nb), k_ff(nb, nb);
  for (int j = 0; j < nb; ++j) {
    for (int i = 0; i < nb; ++i) {
      l_ff(i, j) = op_.l_bb(free_b[i], free_b[j]);
      k_ff(i, j) = op_.k_add(free_b[i], free_b[j]);
    }
  }
  const Eigen::LLT<Eigen::MatrixXd> l_llt(l_ff);
  if (l_llt.info() != Eigen::Success)
    throw std::runtime_error(
        "CoupledBody: host compliance at the new boundary is not positive definite");
  Eigen::MatrixXd s_a = l_llt.solve(Eigen::MatrixXd::Identity(nb, nb));
  s_a = (0.5 * (s_a + s_a.transpose())).eval();
  const Eigen::LDLT<Eigen::MatrixXd> sk(s_a + k_ff);
  if (sk.info() != Eigen::Success)
    throw std::runtime_error("CoupledBody: coupled boundary stiffness could not be factored");
  const Eigen::MatrixXd g_ff = k_ff * sk.solve(s_a);
  op_.g.setZero(m3, m3);
  for (int j = 0; j < nb; ++j)
    for (int i = 0; i < nb; ++i) op_.g(free_b[i], free_b[j]) = 0.5 * (g_ff(i, j) + g_ff(j, i));
  if (!op_.g.allFinite()) throw std::runtime_error("CoupledBody: coupling operator is not finite");
  timing_.operator_s = seconds_since(t0);
}

std::uint64_t CoupledBody::cache_key() const {
  CacheKey key;
  key.add_mesh(*host_, material_);
  key.add(solver_->fixed_nodes());
  key.add(boundary_nodes_);
  key.add(std::vector<int>(contact_nodes_.begin(), contact_nodes_.begin() + num_host_contact_));
  for (const auto& tie : ties_) {
    std::vector<std::array<int, 3>> host_slots(tie.host_nodes().size());
    for (std::size_t k = 0; k < host_slots.size(); ++k)
      for (int a = 0; a < 3; ++a) host_slots[k][a] = boundary_slot_[tie.host_nodes()[k][a]];
    key.add_mesh(tie.geometry(), tie.material());
    key.add(tie.fixed_nodes());
    key.add(tie.tied_nodes());
    key.add(host_slots);
    key.add(tie.weights());
  }
  return key.value();
}

void CoupledBody::solve_contact_columns(const std::vector<int>& slots, Eigen::MatrixXd& x,
                                        fem::SolveWorkspace* ws, IterativeReport* iterations) const {
  if (!finalized_) throw std::logic_error("CoupledBody::solve_contact_columns before finalize");
  const auto& reduced = solver_->reduced_index();
  const int nf = solver_->num_free_dofs();
  const int m3 = static_cast<int>(op_.l_bb.rows());
  const int n = static_cast<int>(slots.size());
  for (int s : slots) {
    if (s < 0 || s >= static_cast<int>(contact_nodes_.size())) {
      throw std::invalid_argument("CoupledBody::solve_contact_columns: contact slot " +
                                  std::to_string(s) + " out of range");
    }
  }
  bool on_tie = false;
  for (int s : slots) on_tie = on_tie || s >= num_host_contact_;
  if (on_tie) {
    // Slots on an exposed tie: their equivalent host loads, one coupled solve (two with ties;
    // the ITERATIVE baseline iterates G inside it, counted as for the host's slots).
    Eigen::MatrixXd rhs;
    tie_slot_loads(slots, rhs, ws);
    if (rhs.isZero(0.0)) {  // slots on exposed sliding meshes only: no force on A
      x.setZero(nf, 3 * n);
      return;
    }
    coupled_solve_reduced(rhs, x, ws, iterations);
    return;
  }
  Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(nf, 3 * n), lb, glb;
  for (int j = 0; j < n; ++j)
    for (int a = 0; a < 3; ++a) rhs(reduced[3 * contact_nodes_[slots[j]] + a], 3 * j + a) = 1.0;
  if (m3 > 0) {
    // Coupled column in one solve: L (e_i + P_b^T f_b) with the tie's boundary force
    // f_b = -G L_A[b, i] (Woodbury on the tie stiffness: L = L_A - L_A[:,b] G L_A[b,:]).
    lb.resize(m3, 3 * n);
    for (int j = 0; j < n; ++j) lb.middleCols(3 * j, 3) = op_.l_sb.middleRows(3 * slots[j], 3).transpose();
    apply_coupling(lb, glb, iterations);
    for (int r = 0; r < m3; ++r) {
      const int red = reduced[3 * boundary_nodes_[r / 3] + r % 3];
      if (red >= 0) rhs.row(red) -= glb.row(r);
    }
  }
  if (ws != nullptr) solver_->solve_reduced(rhs, x, *ws);
  else solver_->solve_reduced(rhs, x);
}

void CoupledBody::tie_slot_loads(const std::vector<int>& slots, Eigen::MatrixXd& rhs,
                                 fem::SolveWorkspace* ws) const {
  const auto& reduced = solver_->reduced_index();
  const auto& free = solver_->free_dofs();
  const int nf = solver_->num_free_dofs();
  const int n = static_cast<int>(slots.size());
  const int n3a = 3 * static_cast<int>(host_->num_vertices());
  rhs.setZero(nf, 3 * n);
  for (int j = 0; j < n; ++j) {
    if (slots[j] >= num_host_contact_) continue;
    for (int a = 0; a < 3; ++a) rhs(reduced[3 * contact_nodes_[slots[j]] + a], 3 * j + a) = 1.0;
  }
  for (std::size_t t = 0; t < ties_.size(); ++t) {
    if (tie_offset_.empty() || tie_offset_[t] < 0) continue;
    std::vector<int> cols;
    for (int j = 0; j < n; ++j)
      if (slots[j] >= num_host_contact_ && contact_tie_[slots[j] - num_host_contact_] == static_cast<int>(t))
        cols.push_back(j);
    if (cols.empty()) continue;
    const int nb3 = 3 * static_cast<int>(ties_[t].geometry().num_vertices());
    Eigen::MatrixXd f = Eigen::MatrixXd::Zero(nb3, 3 * static_cast<int>(cols.size()));
    for (std::size_t c = 0; c < cols.size(); ++c) {
      const int v = contact_nodes_[slots[cols[c]]] - tie_offset_[t];
      for (int a = 0; a < 3; ++a) f(3 * v + a, 3 * static_cast<int>(c) + a) = 1.0;
    }
    Eigen::MatrixXd load = Eigen::MatrixXd::Zero(n3a, f.cols());
    ties_[t].add_equivalent_host_loads(f, load, ws);
    for (std::size_t c = 0; c < cols.size(); ++c)
      for (int r = 0; r < nf; ++r)
        rhs.block<1, 3>(r, 3 * cols[c]) = load.block<1, 3>(free[r], 3 * static_cast<int>(c));
  }
}

void CoupledBody::contact_rows(const std::vector<int>& slots, const Eigen::MatrixXd& x,
                               Eigen::MatrixXd& rows, fem::SolveWorkspace* ws,
                               Eigen::MatrixXd* sliding) const {
  const auto& reduced = solver_->reduced_index();
  const auto& free = solver_->free_dofs();
  const int s3 = 3 * static_cast<int>(contact_nodes_.size());
  const int k = static_cast<int>(x.cols());
  if (k != 3 * static_cast<int>(slots.size()))
    throw std::invalid_argument("CoupledBody::contact_rows: columns and slots differ");
  rows.resize(s3, k);
  if (sliding != nullptr) sliding->setZero(sliding_.size(), k);
  for (int r = 0; r < 3 * num_host_contact_; ++r)
    rows.row(r) = x.row(reduced[3 * contact_nodes_[r / 3] + r % 3]);
  if (!has_exposed_contact()) return;
  const int n3a = 3 * static_cast<int>(host_->num_vertices());
  Eigen::MatrixXd u_a = Eigen::MatrixXd::Zero(n3a, k), u_b;
  for (int r = 0; r < static_cast<int>(free.size()); ++r) u_a.row(free[r]) = x.row(r);
  for (std::size_t t = 0; t < ties_.size(); ++t) {
    if (tie_offset_[t] < 0) continue;
    const int nb3 = 3 * static_cast<int>(ties_[t].geometry().num_vertices());
    Eigen::MatrixXd f = Eigen::MatrixXd::Zero(nb3, k);
    for (std::size_t j = 0; j < slots.size(); ++j) {
      const int s = slots[j];
      if (s < num_host_contact_ || contact_tie_[s - num_host_contact_] != static_cast<int>(t)) continue;
      const int v = contact_nodes_[s] - tie_offset_[t];
      for (int a = 0; a < 3; ++a) f(3 * v + a, 3 * static_cast<int>(j) + a) = 1.0;
    }
    ties_[t].displacements(u_a, f, u_b, ws);
    for (int s = num_host_contact_; s < static_cast<int>(contact_nodes_.size()); ++s) {
      if (contact_tie_[s - num_host_contact_] != static_cast<int>(t)) continue;
      rows.middleRows(3 * s, 3) = u_b.middleRows(3 * (contact_nodes_[s] - tie_offset_[t]), 3);
    }
  }
  if (exposed_slide_slots_) slide_rows(slots, rows, ws, sliding);
}

// contact_rows on the exposed sliding meshes: B's rows of its own columns, L_B[slot nodes, node]
// (zero for every other column: B moves under A's forces only through the sliding rows, which
// the LCP carries), and their sliding rows' part, J_B L_B[:, node] = -n_k . L_B(k, node).
void CoupledBody::slide_rows(const std::vector<int>& slots, Eigen::MatrixXd& rows,
                             fem::SolveWorkspace* ws, Eigen::MatrixXd* sliding) const {
  Eigen::MatrixXd f, u;
  std::vector<int> cols;
  for (std::size_t i = 0; i < exposed_slides_.size(); ++i) {
    const ExposedSlide& e = exposed_slides_[i];
    if (e.coupling == nullptr) continue;
    for (int s = num_host_contact_; s < static_cast<int>(contact_nodes_.size()); ++s)
      if (contact_slide_[s - num_host_contact_] == static_cast<int>(i))
        rows.middleRows(3 * s, 3).setZero();
    cols.clear();
    for (std::size_t j = 0; j < slots.size(); ++j)
      if (slots[j] >= num_host_contact_ &&
          contact_slide_[slots[j] - num_host_contact_] == static_cast<int>(i))
        cols.push_back(static_cast<int>(j));
    if (cols.empty()) continue;
    const SlidingCoupling& sl = *e.coupling;
    f.setZero(3 * static_cast<int>(sl.geometry().num_vertices()),
              3 * static_cast<int>(cols.size()));
    for (std::size_t c = 0; c < cols.size(); ++c) {
      const int v = contact_nodes_[slots[cols[c]]] - e.offset;
      for (int a = 0; a < 3; ++a) f(3 * v + a, 3 * static_cast<int>(c) + a) = 1.0;
    }
    sl.operator_b().apply(f, u, ws);
    for (std::size_t c = 0; c < cols.size(); ++c) {
      const int j = 3 * cols[c], uc = 3 * static_cast<int>(c);
      for (int s = num_host_contact_; s < static_cast<int>(contact_nodes_.size()); ++s) {
        if (contact_slide_[s - num_host_contact_] != static_cast<int>(i)) continue;
        rows.block(3 * s, j, 3, 3) = u.block(3 * (contact_nodes_[s] - e.offset), uc, 3, 3);
      }
      if (sliding == nullptr) continue;
      for (int r = 0; r < sl.size(); ++r) {
        const SlidingPair& p = sl.pairs()[static_cast<std::size_t>(r)];
        sliding->block(e.first_row + r, j, 1, 3) =
            -p.normal.transpose() * u.block(3 * p.embedded_node, uc, 3, 3);
      }
    }
  }
}

void CoupledBody::add_contact_loads(const std::vector<int>& slots,
                                    const std::vector<mesh::Vec3>& forces_n,
                                    Eigen::VectorXd& host_load_n, fem::SolveWorkspace* ws) const {
  if (slots.size() != forces_n.size())
    throw std::invalid_argument("CoupledBody::add_contact_loads: sizes differ");
  for (std::size_t k = 0; k < slots.size(); ++k) {
    const int s = slots[k];
    if (s < 0 || s >= static_cast<int>(contact_nodes_.size()) || !forces_n[k].allFinite())
      throw std::invalid_argument("CoupledBody::add_contact_loads: bad slot or force at entry " +
                                  std::to_string(k));
    if (s < num_host_contact_) host_load_n.segment<3>(3 * contact_nodes_[s]) += forces_n[k];
  }
  if (!has_exposed_contact()) return;
  Eigen::VectorXd f_b;
  for (std::size_t t = 0; t < ties_.size(); ++t) {
    if (tie_offset_[t] < 0 || !tie_contact_forces(static_cast<int>(t), slots, forces_n, f_b)) continue;
    Eigen::MatrixXd load = Eigen::MatrixXd::Zero(host_load_n.size(), 1);
    ties_[t].add_equivalent_host_loads(Eigen::MatrixXd(f_b), load, ws);
    host_load_n += load.col(0);
  }
}

bool CoupledBody::slide_contact_forces(int slide, const std::vector<int>& slots,
                                       const std::vector<mesh::Vec3>& forces_n,
                                       Eigen::VectorXd& forces_b) const {
  const SlidingCoupling* sl = exposed_slide(slide);
  if (sl == nullptr || !exposed_slide_slots_) return false;
  const ExposedPart part{contact_nodes_, num_host_contact_, contact_slide_, slide,
                         exposed_slides_[static_cast<std::size_t>(slide)].offset,
                         static_cast<int>(sl->geometry().num_vertices())};
  return part_contact_forces(part, slots, forces_n, forces_b);
}

bool CoupledBody::tie_contact_forces(int tie, const std::vector<int>& slots,
                                     const std::vector<mesh::Vec3>& forces_n,
                                     Eigen::VectorXd& forces_b) const {
  if (tie < 0 || tie >= static_cast<int>(ties_.size()) || tie_offset_.empty() ||
      tie_offset_[tie] < 0)
    return false;
  const ExposedPart part{contact_nodes_, num_host_contact_, contact_tie_, tie, tie_offset_[tie],
                         static_cast<int>(ties_[tie].geometry().num_vertices())};
  return part_contact_forces(part, slots, forces_n, forces_b);
}

void CoupledBody::set_iterative(const IterativeOptions& options) {
  if (finalized_) throw std::logic_error("CoupledBody::set_iterative after finalize");
  if (!(options.tolerance > 0.0) || options.max_iterations < 1) {
    throw std::invalid_argument(
        "CoupledBody::set_iterative: tolerance must be > 0, iterations >= 1");
  }
  iterative_requested_ = true;
  iterative_options_ = options;
}

void CoupledBody::apply_coupling(const Eigen::MatrixXd& in, Eigen::MatrixXd& out,
                                 IterativeReport* iterations) const {
  if (iterative_) {
    iterative_->apply(in, out, iterations);
    return;
  }
  out.noalias() = op_.g * in;
}

void CoupledBody::host_displacement(const std::vector<int>& slots,
                                    const std::vector<mesh::Vec3>& forces_n,
                                    Eigen::VectorXd& u_host_m, fem::SolveWorkspace* ws) const {
  if (slots.size() != forces_n.size())
    throw std::invalid_argument("CoupledBody::host_displacement: sizes differ");
  const int n3 = 3 * static_cast<int>(host_->num_vertices());
  Eigen::VectorXd f = Eigen::VectorXd::Zero(n3);
  if (has_exposed_contact()) {
    for (int s : slots) {
      if (s < num_host_contact_) continue;
      // A force on an exposed tie: its equivalent host load, one coupled solve.
      add_contact_loads(slots, forces_n, f, ws);
      coupled_displacement(f, u_host_m, ws);
      return;
    }
  }
  const int m3 = static_cast<int>(op_.l_bb.rows());
  Eigen::VectorXd v = Eigen::VectorXd::Zero(m3);
  for (std::size_t k = 0; k < slots.size(); ++k) {
    const int s = slots[k];
    if (s < 0 || s >= static_cast<int>(contact_nodes_.size()) || !forces_n[k].allFinite()) {
      throw std::invalid_argument("CoupledBody::host_displacement: bad slot or force at entry " +
                                  std::to_string(k));
    }
    f.segment<3>(3 * contact_nodes_[s]) += forces_n[k];
    if (m3 > 0) v.noalias() += op_.l_sb.middleRows(3 * s, 3).transpose() * forces_n[k];
  }
  if (m3 > 0) {
    // B's force on A: f_b = -K_add u_b with the coupled boundary displacement
    // u_b = (I + L_bb K_add)^-1 v, i.e. f_b = -G v. Taken as -G v: forming u_b = v - L_bb G v
    // first cancels almost all of v when B is much stiffer than A, and K_add then multiplies
    // that cancellation error (artery/brain 1e6: 2e-4 field error, B's strain energy 1e4 x off).
    Eigen::MatrixXd gv;
    apply_coupling(v, gv);
    for (int r = 0; r < m3; ++r) f[3 * boundary_nodes_[r / 3] + r % 3] -= gv(r, 0);
  }
  if (ws != nullptr) solver_->solve(f, u_host_m, *ws);
  else solver_->solve(f, u_host_m);
}

Eigen::Matrix3d CoupledBody::host_block(int slot_i, int slot_j) const {
  Eigen::Matrix3d out;
  Eigen::VectorXd f = Eigen::VectorXd::Zero(3 * static_cast<int>(host_->num_vertices())), u;
  for (int a = 0; a < 3; ++a) {
    f.setZero();
    f[3 * contact_nodes_.at(slot_j) + a] = 1.0;
    solver_->solve(f, u);
    out.col(a) = u.segment<3>(3 * contact_nodes_.at(slot_i));
  }
  return out;
}

}  // namespace neurosim::interaction
