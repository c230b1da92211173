#include "server/fem/static_solver.hpp"

#include "common/clock.hpp"
#include "common/process_stats.hpp"
#include "server/fem/factor_cache.hpp"
#include "server/fem/power_iteration.hpp"
#include "server/fem/supports.hpp"

#include <Eigen/Cholesky>
#include <Eigen/CholmodSupport>
#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <atomic>
#include <iomanip>
#include <mutex>
#include <numeric>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>

namespace neurosim::fem {

namespace {

using common::Clock;
using common::seconds_since;

// Eigen's supernodal LL^T with access to CHOLMOD's factor and common (for solve2, memory, rcond).
class SupernodalFactor : public Eigen::CholmodSupernodalLLT<SparseMatrix, Eigen::Lower> {
 public:
  cholmod_factor* factor() const { return this->m_cholmodFactor; }
  cholmod_common& common() const { return const_cast<SupernodalFactor*>(this)->cholmod(); }
  // Takes a symbolic factor made elsewhere (analyze_ordered) as if analyzePattern had made it.
  void adopt_analysis(cholmod_factor* f) { take(f, false); }
  // Takes a numeric factor made elsewhere (the disk cache) as if analyzePattern and factorize
  // had made it.
  void adopt(cholmod_factor* f) { take(f, true); }

 private:
  void take(cholmod_factor* f, bool factorized) {
    if (this->m_cholmodFactor) cholmod_free_factor(&this->m_cholmodFactor, &common());
    this->m_cholmodFactor = f;
    this->m_isInitialized = true;
    this->m_info = Eigen::Success;
    this->m_analysisIsOk = true;
    this->m_factorizationIsOk = factorized;
  }
};

cholmod_dense dense_view(double* data, std::size_t rows, std::size_t cols) {
  cholmod_dense d{};
  d.nrow = rows;
  d.ncol = cols;
  d.nzmax = rows * cols;
  d.d = rows;
  d.x = data;
  d.z = nullptr;
  d.xtype = CHOLMOD_REAL;
  d.dtype = CHOLMOD_DOUBLE;
  return d;
}

}  // namespace

// The scratch of solves: its own CHOLMOD common (status, allocation) and dense buffers that
// cholmod_solve2 resizes once and then reuses.
struct SolveWorkspace::Impl {
  cholmod_common common{};
  cholmod_dense* x1{nullptr};
  cholmod_dense* y1{nullptr};
  cholmod_dense* e1{nullptr};
  cholmod_dense* xm{nullptr};
  cholmod_dense* ym{nullptr};
  cholmod_dense* em{nullptr};
  Eigen::VectorXd rhs;   // reduced right-hand side, num_free_dofs
  Eigen::VectorXd full;  // 3N scratch (residual check)

  Impl() { cholmod_start(&common); }
  ~Impl() {
    for (cholmod_dense** d : {&x1, &y1, &e1, &xm, &ym, &em}) {
      if (*d) {
        cholmod_free_dense(d, &common);
      }
    }
    cholmod_finish(&common);
  }
  Impl(const Impl&) = delete;
  Impl& operator=(const Impl&) = delete;

  // x := K_ff^-1 b for b (n x m), reusing the buffers `x`, `y`, `e`; the factor is only read.
  void solve(const cholmod_factor* factor, const double* b_data, std::size_t n, std::size_t m,
             cholmod_dense** x, cholmod_dense** y, cholmod_dense** e) {
    cholmod_dense b = dense_view(const_cast<double*>(b_data), n, m);
    if (!cholmod_solve2(CHOLMOD_A, const_cast<cholmod_factor*>(factor), &b, nullptr, x, nullptr, y, e,
                        &common)) {
      throw std::runtime_error("StaticSolver: CHOLMOD solve failed (status " +
                               std::to_string(common.status) + ")");
    }
  }
};

SolveWorkspace::SolveWorkspace() : impl_(std::make_unique<Impl>()) {}
SolveWorkspace::~SolveWorkspace() = default;
SolveWorkspace::SolveWorkspace(SolveWorkspace&&) noexcept = default;
SolveWorkspace& SolveWorkspace::operator=(SolveWorkspace&&) noexcept = default;

struct StaticSolver::Impl {
  SupernodalFactor llt;
  // Full K. A factor read from the cache leaves it unassembled: the mesh and materials are kept
  // until stiffness() first needs them (once, whichever thread asks first).
  SparseMatrix k;
  std::once_flag k_once;
  std::unique_ptr<mesh::TetMesh> deferred_mesh;
  MaterialMap deferred_materials;
  // The solver's own workspace, for the overloads without one (set-up, offline use).
  std::mutex mutex;
  SolveWorkspace shared;
  std::atomic<std::uint64_t> shared_uses{0};
};

StaticSolver::StaticSolver(const mesh::TetMesh& mesh, const MaterialMap& materials,
                           const std::vector<int>& fixed_nodes, const SolverOptions& options)
    : impl_(std::make_unique<Impl>()),
      options_(options),
      num_nodes_(static_cast<int>(mesh.num_vertices())) {
  const std::string where = "StaticSolver (mesh '" + mesh.source() + "')";
  if (num_nodes_ == 0 || mesh.num_tets() == 0) {
    throw std::invalid_argument(where + ": empty mesh");
  }
  if (!(options_.residual_tolerance > 0.0) || !std::isfinite(options_.min_rcond)) {
    throw std::invalid_argument(where +
                                ": SolverOptions residual_tolerance must be > 0, min_rcond finite");
  }
  materials.validate(mesh.num_tets());

  // Fixed nodes: in range, deduplicated.
  for (int v : fixed_nodes) {
    if (v < 0 || v >= num_nodes_) {
      throw std::invalid_argument(where + ": fixed node " + std::to_string(v) +
                                  " out of range [0, " + std::to_string(num_nodes_) + ")");
    }
  }
  fixed_nodes_ = fixed_nodes;
  std::sort(fixed_nodes_.begin(), fixed_nodes_.end());
  fixed_nodes_.erase(std::unique(fixed_nodes_.begin(), fixed_nodes_.end()), fixed_nodes_.end());
  std::vector<char> is_fixed(num_nodes_, 0);
  for (int v : fixed_nodes_) {
    is_fixed[v] = 1;
  }

  // A free node that no tetrahedron holds has a zero row in K.
  std::vector<char> used(num_nodes_, 0);
  for (const auto& t : mesh.tets()) {
    for (int a : t) {
      used[a] = 1;
    }
  }
  for (int v = 0; v < num_nodes_; ++v) {
    if (!used[v] && !is_fixed[v]) {
      throw std::invalid_argument(
          where + ": node " + std::to_string(v) +
          " belongs to no tetrahedron and is not fixed: the stiffness is singular");
    }
  }

  // Rigid-body modes: every connected part needs >= 3 non-collinear fixed nodes.
  if (options_.check_rigid_modes) {
    const std::vector<UnsupportedPart> bad = unsupported_parts(mesh, fixed_nodes_);
    if (!bad.empty()) {
      const UnsupportedPart& p = bad.front();
      throw std::invalid_argument(
          where + ": insufficient fixed nodes, the stiffness is singular: connected part " +
          std::to_string(p.part) + " (" + std::to_string(p.nodes.size()) + " nodes, first node " +
          std::to_string(p.nodes.front()) + ") " + p.problem +
          "; fix at least 3 non-collinear nodes of every part");
    }
  }

  // Dof numbering of the reduced system (keeps the original order, so rows stay sorted).
  const int ndof = 3 * num_nodes_;
  reduced_index_.assign(ndof, -1);
  free_dofs_.clear();
  for (int d = 0; d < ndof; ++d) {
    if (!is_fixed[d / 3]) {
      reduced_index_[d] = static_cast<int>(free_dofs_.size());
      free_dofs_.push_back(d);
    }
  }
  const int nf = static_cast<int>(free_dofs_.size());
  info_.num_dofs = ndof;
  info_.num_free_dofs = nf;
  impl_->shared.impl_->rhs.resize(nf);
  impl_->shared.impl_->full.resize(ndof);
  SparseMatrix& k = impl_->k;
  auto assemble = [&] {
    const auto ta = Clock::now();
    StiffnessAssembler(mesh, materials.element()).assemble(mesh, materials, k);
    info_.assembly_s = seconds_since(ta);
    info_.stiffness_nnz = k.nonZeros();
  };
  if (nf == 0) {
    assemble();
    return;  // everything fixed: u = 0, nothing to factor
  }

  auto& llt = impl_->llt;
  cholmod_common& c = llt.common();
  c.print = options_.cholmod_verbose ? 3 : 0;
  const char* source = "SolverOptions::max_factor_bytes";
  const double limit = options_.max_factor_bytes > 0.0 ? options_.max_factor_bytes
                                                       : common::memory_available_bytes(&source);
  double lnz = 0.0;  // nnz(L), CHOLMOD's count
  std::string cache_file;
  std::uint64_t cache_key = 0;
  if (!options_.factor_cache_dir.empty()) {
    // The factor of this very problem from an earlier start, found by K_ff's inputs (a too
    // large one is left to the analysis below, which refuses it with its numbers).
    auto t0 = Clock::now();
    cache_key = factor_key(mesh, materials, fixed_nodes_, static_cast<int>(options_.ordering));
    cache_file = factor_file(options_.factor_cache_dir, cache_key);
    const FactorLoad cached = load_factor(cache_file, cache_key, nf, limit, c);
    if (cached.factor != nullptr) {
      llt.adopt(cached.factor);
      info_.from_cache = true;
      info_.ordering = ordering_name(options_.ordering);
      lnz = cached.lnz;
      // K itself only if asked for (same inputs: the same K the factor was made of).
      impl_->deferred_mesh = std::make_unique<mesh::TetMesh>(mesh);
      impl_->deferred_materials = materials;
    }
    info_.cache_s = seconds_since(t0);
  }
  if (!info_.from_cache) {
    assemble();
    factorize(lower_free_block(k), where, limit, source, lnz);
    if (!cache_file.empty()) {
      const auto t0 = Clock::now();
      save_factor(cache_file, cache_key, *llt.factor(), lnz);
      info_.cache_s += seconds_since(t0);
    }
  }
  const cholmod_factor* l = llt.factor();
  info_.rcond = cholmod_rcond(llt.factor(), &c);
  if (!(info_.rcond >= options_.min_rcond)) {
    std::ostringstream msg;
    msg << where << ": stiffness K_ff is numerically singular (CHOLMOD rcond " << info_.rcond
        << " < " << options_.min_rcond
        << "): are there enough fixed nodes in every part of the mesh?";
    throw std::runtime_error(msg.str());
  }
  info_.supernodal = l->is_super != 0;
  info_.factor_nnz = static_cast<long long>(lnz);
  info_.factor_entries = static_cast<long long>(l->is_super ? l->xsize : l->nzmax);
  info_.factor_bytes = info_.factor_entries * sizeof(double) + l->ssize * sizeof(int) +
                       3 * (l->nsuper + 1) * sizeof(int) + 2 * l->n * sizeof(int);
}

SparseMatrix StaticSolver::lower_free_block(const SparseMatrix& k) const {
  // Column by column, the fixed dofs eliminated.
  const int nf = num_free_dofs();
  SparseMatrix kff(nf, nf);
  std::vector<int> outer(nf + 1, 0);
  std::vector<int> inner;
  std::vector<double> values;
  inner.reserve(k.nonZeros() / 2 + nf);
  values.reserve(k.nonZeros() / 2 + nf);
  for (int jr = 0; jr < nf; ++jr) {
    for (SparseMatrix::InnerIterator it(k, free_dofs_[jr]); it; ++it) {
      const int ir = reduced_index_[it.row()];
      if (ir >= jr) {
        inner.push_back(ir);
        values.push_back(it.value());
      }
    }
    outer[jr + 1] = static_cast<int>(inner.size());
  }
  kff.resizeNonZeros(static_cast<Eigen::Index>(inner.size()));
  std::copy(outer.begin(), outer.end(), kff.outerIndexPtr());
  std::copy(inner.begin(), inner.end(), kff.innerIndexPtr());
  std::copy(values.begin(), values.end(), kff.valuePtr());
  return kff;
}

const SparseMatrix& StaticSolver::stiffness() const {
  std::call_once(impl_->k_once, [this] {
    if (impl_->deferred_mesh == nullptr) return;
    const mesh::TetMesh& mesh = *impl_->deferred_mesh;
    StiffnessAssembler(mesh, impl_->deferred_materials.element())
        .assemble(mesh, impl_->deferred_materials, impl_->k);
    impl_->deferred_mesh.reset();
    impl_->deferred_materials = MaterialMap{};
  });
  return impl_->k;
}

void StaticSolver::factorize(const SparseMatrix& kff, const std::string& where, double limit,
                             const char* source, double& lnz) {
  auto& llt = impl_->llt;
  cholmod_common& c = llt.common();
  const int nf = num_free_dofs();
  auto t0 = Clock::now();
  {
    // Each free dof's node: the node-graph ordering keeps a node's rows together.
    std::vector<int> node_of(static_cast<std::size_t>(nf));
    for (int r = 0; r < nf; ++r) node_of[static_cast<std::size_t>(r)] = free_dofs_[r] / 3;
    cholmod_factor* symbolic = analyze_ordered(kff, options_.ordering, node_of, c);
    if (symbolic != nullptr) llt.adopt_analysis(symbolic);
  }
  info_.analyze_s = seconds_since(t0);
  info_.factor_flops = c.fl;
  info_.ordering = ordering_name(options_.ordering);
  if (options_.ordering == FactorOrdering::kCholmodDefault && c.selected >= 0 &&
      c.selected <= CHOLMOD_MAXMETHODS) {
    const int chosen = c.method[c.selected].ordering;
    info_.ordering += chosen == CHOLMOD_AMD ? ":amd" : chosen == CHOLMOD_METIS ? ":metis" : ":other";
  }
  if (!llt.factor()) {
    throw std::runtime_error(where + ": CHOLMOD analysis failed (status " +
                             std::to_string(c.status) + ")");
  }
  {
    // The numeric factor's size, exact from the symbolic analysis (supernodal: the values of
    // every supernode; simplicial: nnz(L)), with the same count as FactorInfo::factor_bytes.
    const cholmod_factor* ls = llt.factor();
    const double entries = ls->is_super ? static_cast<double>(ls->xsize) : c.lnz;
    const double needed = entries * sizeof(double) +
                          static_cast<double>(ls->ssize) * sizeof(int) +
                          3.0 * static_cast<double>(ls->nsuper + 1) * sizeof(int) +
                          2.0 * static_cast<double>(ls->n) * sizeof(int);
    if (needed > limit) {
      std::ostringstream msg;
      msg << where << ": the factor of K_ff needs " << std::fixed << std::setprecision(1)
          << needed / 1048576.0 << " MiB (CHOLMOD's symbolic analysis: " << nf
          << " free dofs, nnz(L) " << static_cast<long long>(c.lnz) << "), more than the "
          << limit / 1048576.0 << " MiB available (" << source << ")"
          << ": refused before factoring; use a coarser mesh or a machine with more memory";
      throw FactorTooLarge(msg.str(), needed, limit);
    }
  }
  t0 = Clock::now();
  llt.factorize(kff);
  info_.factorize_s = seconds_since(t0);
  const cholmod_factor* l = llt.factor();
  if (llt.info() != Eigen::Success) {
    std::string msg = where +
                      ": stiffness K_ff is singular or indefinite (CHOLMOD stopped at column " +
                      std::to_string(l->minor) + " of " + std::to_string(nf);
    if (l->minor < static_cast<std::size_t>(nf)) {
      const int dof = free_dofs_[static_cast<int*>(l->Perm)[l->minor]];
      msg += ", node " + std::to_string(dof / 3) + " axis " + std::to_string(dof % 3);
    }
    throw std::runtime_error(msg + "): too few fixed nodes (rigid-body modes) or bad materials?");
  }
  lnz = c.lnz;
}

StaticSolver::~StaticSolver() = default;
StaticSolver::StaticSolver(StaticSolver&&) noexcept = default;
StaticSolver& StaticSolver::operator=(StaticSolver&&) noexcept = default;

void StaticSolver::check_forces(const Eigen::VectorXd& forces_n, const char* what) const {
  if (forces_n.size() != num_dofs()) {
    throw std::invalid_argument(std::string("StaticSolver: ") + what + " has " +
                                std::to_string(forces_n.size()) +
                                " entries, expected 3N = " + std::to_string(num_dofs()));
  }
  for (Eigen::Index i = 0; i < forces_n.size(); ++i) {
    if (!std::isfinite(forces_n[i])) {
      throw std::invalid_argument(std::string("StaticSolver: ") + what +
                                  ": non-finite value at node " + std::to_string(i / 3) + " axis " +
                                  std::to_string(i % 3));
    }
  }
}

void StaticSolver::check_residual(Eigen::VectorXd& r, const Eigen::VectorXd& u_m,
                                  const Eigen::VectorXd& forces_n,
                                  const std::vector<char>* constrained) const {
  r.noalias() = stiffness() * u_m;
  // Scale: the applied forces or K u over all dofs (the reactions included), so that a problem
  // loaded only by prescribed displacements (f = 0 and K u ~ 0 on the free dofs) has one.
  double res2 = 0.0, ref2 = 0.0, ku2 = 0.0;
  for (int d = 0; d < num_dofs(); ++d) {
    ku2 += r[d] * r[d];
    if (reduced_index_[d] < 0 || (constrained && (*constrained)[d])) {
      continue;
    }
    const double f = forces_n.size() ? forces_n[d] : 0.0;
    res2 += (r[d] - f) * (r[d] - f);
    ref2 += f * f;
  }
  const double scale = std::sqrt(std::max(ref2, ku2));
  if (std::sqrt(res2) > options_.residual_tolerance * scale) {
    std::ostringstream msg;
    msg << "StaticSolver: residual check failed: ||K u - f|| = " << std::sqrt(res2) << " N > "
        << options_.residual_tolerance << " * " << scale << " N (ill-conditioned stiffness?)";
    throw std::runtime_error(msg.str());
  }
}

void StaticSolver::solve_free(const Eigen::VectorXd& forces_n, Eigen::VectorXd& u_m,
                              SolveWorkspace::Impl& ws) const {
  check_forces(forces_n, "forces");
  u_m.setZero(num_dofs());
  const int nf = num_free_dofs();
  if (nf == 0) {
    return;
  }
  ws.rhs.resize(nf);
  for (int r = 0; r < nf; ++r) {
    ws.rhs[r] = forces_n[free_dofs_[r]];
  }
  ws.solve(impl_->llt.factor(), ws.rhs.data(), nf, 1, &ws.x1, &ws.y1, &ws.e1);
  const double* x = static_cast<const double*>(ws.x1->x);
  for (int r = 0; r < nf; ++r) {
    u_m[free_dofs_[r]] = x[r];
  }
  if (!u_m.allFinite()) {
    throw std::runtime_error("StaticSolver: solve produced non-finite displacements");
  }
  if (options_.check_residual) {
    check_residual(ws.full, u_m, forces_n, nullptr);
  }
}

void StaticSolver::solve(const Eigen::VectorXd& forces_n, Eigen::VectorXd& u_m) const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  impl_->shared_uses.fetch_add(1, std::memory_order_relaxed);
  solve_free(forces_n, u_m, *impl_->shared.impl_);
}

void StaticSolver::solve(const Eigen::VectorXd& forces_n, Eigen::VectorXd& u_m,
                         SolveWorkspace& ws) const {
  solve_free(forces_n, u_m, *ws.impl_);
}

std::uint64_t StaticSolver::shared_workspace_uses() const {
  return impl_->shared_uses.load(std::memory_order_relaxed);
}

Eigen::VectorXd StaticSolver::solve(const Eigen::VectorXd& forces_n) const {
  Eigen::VectorXd u;
  solve(forces_n, u);
  return u;
}

void StaticSolver::solve_reduced(const Eigen::MatrixXd& b, Eigen::MatrixXd& x) const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  impl_->shared_uses.fetch_add(1, std::memory_order_relaxed);
  solve_reduced(b, x, impl_->shared);
}

void StaticSolver::solve_reduced(const Eigen::MatrixXd& b, Eigen::MatrixXd& x, SolveWorkspace& wsp) const {
  const int nf = num_free_dofs();
  if (b.rows() != nf) {
    throw std::invalid_argument("StaticSolver::solve_reduced: right-hand side has " +
                                std::to_string(b.rows()) + " rows, expected " + std::to_string(nf) +
                                " free dofs");
  }
  if (!b.allFinite()) {
    throw std::invalid_argument("StaticSolver::solve_reduced: non-finite right-hand side");
  }
  x.resize(nf, b.cols());
  if (nf == 0 || b.cols() == 0) {
    return;
  }
  SolveWorkspace::Impl& ws = *wsp.impl_;
  ws.solve(impl_->llt.factor(), b.data(), nf, b.cols(), &ws.xm, &ws.ym, &ws.em);
  std::copy_n(static_cast<const double*>(ws.xm->x), x.size(), x.data());
  if (!x.allFinite()) {
    throw std::runtime_error("StaticSolver::solve_reduced: non-finite solution");
  }
}

std::vector<int> StaticSolver::node_dofs(const std::vector<int>& nodes,
                                        const Eigen::VectorXd& displacements_m, int num_nodes) {
  if (displacements_m.size() != 3 * static_cast<Eigen::Index>(nodes.size())) {
    throw std::invalid_argument(
        "StaticSolver::solve_prescribed: " + std::to_string(displacements_m.size()) +
        " displacement values for " + std::to_string(nodes.size()) + " nodes (need 3 each)");
  }
  std::vector<char> seen(num_nodes, 0);
  std::vector<int> dofs(3 * nodes.size());
  for (std::size_t k = 0; k < nodes.size(); ++k) {
    const int v = nodes[k];
    if (v < 0 || v >= num_nodes) {
      throw std::invalid_argument("StaticSolver::solve_prescribed: node " + std::to_string(v) +
                                  " out of range [0, " + std::to_string(num_nodes) + ")");
    }
    if (seen[v]) {
      throw std::invalid_argument("StaticSolver::solve_prescribed: node " + std::to_string(v) +
                                  " given twice");
    }
    seen[v] = 1;
    for (int a = 0; a < 3; ++a) {
      dofs[3 * k + a] = 3 * v + a;
    }
  }
  return dofs;
}

PrescribedSolution StaticSolver::solve_prescribed(const std::vector<int>& nodes,
                                                  const Eigen::VectorXd& displacements_m,
                                                  const Eigen::VectorXd& forces_n) const {
  return prescribed_per_dof(node_dofs(nodes, displacements_m, num_nodes_), displacements_m,
                            forces_n, nullptr);
}

PrescribedSolution StaticSolver::solve_prescribed(const std::vector<int>& nodes,
                                                  const Eigen::VectorXd& displacements_m,
                                                  const Eigen::VectorXd& forces_n,
                                                  SolveWorkspace& ws) const {
  return prescribed_per_dof(node_dofs(nodes, displacements_m, num_nodes_), displacements_m,
                            forces_n, &ws);
}

PrescribedSolution StaticSolver::solve_prescribed_dofs(
    const std::vector<PrescribedDofs>& prescribed, const Eigen::VectorXd& forces_n) const {
  PrescribedDofList list;
  try {
    list = expand_prescribed(prescribed, num_nodes_, fixed_nodes_);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(std::string("StaticSolver::solve_prescribed_dofs: ") + e.what());
  }
  return solve_prescribed_per_dof(list.dofs, list.values_m, forces_n);
}

PrescribedSolution StaticSolver::solve_prescribed_per_dof(const std::vector<int>& dofs,
                                                          const Eigen::VectorXd& values_m,
                                                          const Eigen::VectorXd& forces_n) const {
  return prescribed_per_dof(dofs, values_m, forces_n, nullptr);
}

PrescribedSolution StaticSolver::solve_prescribed_per_dof(const std::vector<int>& dofs,
                                                          const Eigen::VectorXd& values_m,
                                                          const Eigen::VectorXd& forces_n,
                                                          SolveWorkspace& ws) const {
  return prescribed_per_dof(dofs, values_m, forces_n, &ws);
}

PrescribedSolution StaticSolver::prescribed_per_dof(const std::vector<int>& dofs,
                                                    const Eigen::VectorXd& values_m,
                                                    const Eigen::VectorXd& forces_n,
                                                    SolveWorkspace* ws) const {
  const auto reduced_solve = [&](const Eigen::MatrixXd& rhs, Eigen::MatrixXd& x) {
    if (ws != nullptr) solve_reduced(rhs, x, *ws);
    else solve_reduced(rhs, x);
  };
  const int ndof = num_dofs();
  if (values_m.size() != static_cast<Eigen::Index>(dofs.size())) {
    throw std::invalid_argument(
        "StaticSolver::solve_prescribed: " + std::to_string(values_m.size()) +
        " displacement values for " + std::to_string(dofs.size()) + " dofs (need 1 each)");
  }
  if (forces_n.size() != 0) {
    check_forces(forces_n, "forces");
  }
  std::vector<char> constrained(ndof, 0);  // fixed or prescribed dofs
  for (int v : fixed_nodes_) {
    for (int a = 0; a < 3; ++a) {
      constrained[3 * v + a] = 1;
    }
  }
  Eigen::VectorXd u = Eigen::VectorXd::Zero(ndof);
  std::vector<char> prescribed(ndof, 0);
  std::vector<int> free_prescribed;  // prescribed dofs that are free in the factor
  for (std::size_t k = 0; k < dofs.size(); ++k) {
    const int d = dofs[k];
    if (d < 0 || d >= ndof) {
      throw std::invalid_argument("StaticSolver::solve_prescribed: dof " + std::to_string(d) +
                                  " (node " + std::to_string(d / 3) +
                                  ") out of range [0, 3N = " + std::to_string(ndof) + ")");
    }
    if (prescribed[d]) {
      throw std::invalid_argument("StaticSolver::solve_prescribed: node " + std::to_string(d / 3) +
                                  " axis " + std::to_string(d % 3) + " given twice");
    }
    prescribed[d] = 1;
    const double value = values_m[static_cast<Eigen::Index>(k)];
    if (!std::isfinite(value)) {
      throw std::invalid_argument(
          "StaticSolver::solve_prescribed: non-finite displacement at node " +
          std::to_string(d / 3) + " axis " + std::to_string(d % 3));
    }
    u[d] = value;
    constrained[d] = 1;
    if (reduced_index_[d] >= 0) {
      free_prescribed.push_back(d);
    }
  }

  // Eliminated part: K_ff u0 = f_f - K_fc u_c with u_c the values at fixed nodes.
  const int nf = num_free_dofs();
  Eigen::VectorXd uc = Eigen::VectorXd::Zero(ndof);
  for (int v : fixed_nodes_) {
    uc.segment<3>(3 * v) = u.segment<3>(3 * v);
  }
  const Eigen::VectorXd kuc = stiffness() * uc;
  Eigen::MatrixXd b(nf, 1), u0;
  for (int r = 0; r < nf; ++r) {
    b(r, 0) = (forces_n.size() ? forces_n[free_dofs_[r]] : 0.0) - kuc[free_dofs_[r]];
  }
  reduced_solve(b, u0);

  if (!free_prescribed.empty()) {
    // Prescribed free dofs: multipliers lam (their reaction forces) with
    // (E^T K_ff^-1 E) lam = ubar - E^T u0, then u_f = u0 + K_ff^-1 E lam.
    const int m = static_cast<int>(free_prescribed.size());
    Eigen::VectorXd target(m);
    std::vector<int> rows(m);
    for (int c = 0; c < m; ++c) {
      rows[c] = reduced_index_[free_prescribed[c]];
      target[c] = u[free_prescribed[c]] - u0(rows[c], 0);
    }
    // S = E^T K_ff^-1 E by block solves of kBlock unit columns (memory nf x kBlock, not nf x m).
    constexpr int kBlock = 64;
    Eigen::MatrixXd s(m, m), e, g;
    for (int c0 = 0; c0 < m; c0 += kBlock) {
      const int cols = std::min(kBlock, m - c0);
      e.setZero(nf, cols);
      for (int c = 0; c < cols; ++c) {
        e(rows[c0 + c], c) = 1.0;
      }
      reduced_solve(e, g);
      for (int c = 0; c < cols; ++c) {
        for (int r = 0; r < m; ++r) {
          s(r, c0 + c) = g(rows[r], c);
        }
      }
    }
    s = 0.5 * (s + s.transpose()).eval();
    Eigen::LLT<Eigen::MatrixXd> schur(s);
    if (schur.info() != Eigen::Success) {
      throw std::runtime_error(
          "StaticSolver::solve_prescribed: compliance block of the prescribed dofs is not "
          "positive definite");
    }
    const Eigen::VectorXd lam = schur.solve(target);
    // u_f = u0 + K_ff^-1 E lam: one more solve.
    e.setZero(nf, 1);
    for (int c = 0; c < m; ++c) {
      e(rows[c], 0) += lam[c];
    }
    reduced_solve(e, g);
    u0.col(0) += g.col(0);
  }
  for (int r = 0; r < nf; ++r) {
    const int d = free_dofs_[r];
    if (!constrained[d]) {
      u[d] = u0(r, 0);
    }
  }

  PrescribedSolution out;
  out.reaction_n = stiffness() * u;
  if (forces_n.size()) {
    out.reaction_n -= forces_n;
  }
  for (int d = 0; d < ndof; ++d) {
    if (!constrained[d]) {
      out.reaction_n[d] = 0.0;
    }
  }
  if (!u.allFinite() || !out.reaction_n.allFinite()) {
    throw std::runtime_error("StaticSolver::solve_prescribed: non-finite result");
  }
  if (options_.check_residual) {
    if (ws != nullptr) {
      check_residual(ws->impl_->full, u, forces_n, &constrained);
    } else {
      std::lock_guard<std::mutex> lock(impl_->mutex);
      check_residual(impl_->shared.impl_->full, u, forces_n, &constrained);
    }
  }
  out.displacement_m = std::move(u);
  return out;
}

ConditionEstimate StaticSolver::estimate_condition(int max_iterations, double tolerance) const {
  ConditionEstimate est;
  est.rcond_cholmod = info_.rcond;
  const int nf = num_free_dofs();
  if (nf == 0) {
    return est;
  }
  std::mt19937 rng(12345);
  std::uniform_real_distribution<double> dist(-1.0, 1.0);
  Eigen::VectorXd start_max(nf), start_min(nf);
  for (int r = 0; r < nf; ++r) {
    start_max[r] = dist(rng);
  }
  for (int r = 0; r < nf; ++r) {
    start_min[r] = dist(rng);
  }
  // Power iteration: lambda_max of K_ff.
  Eigen::VectorXd full = Eigen::VectorXd::Zero(num_dofs()), kv(num_dofs());
  const SparseMatrix& k = stiffness();
  const PowerIteration hi = power_iteration(
      [&](const Eigen::VectorXd& v, Eigen::VectorXd& w) {
        for (int r = 0; r < nf; ++r) {
          full[free_dofs_[r]] = v[r];
        }
        kv.noalias() = k * full;
        for (int r = 0; r < nf; ++r) {
          w[r] = kv[free_dofs_[r]];
        }
      },
      start_max, max_iterations, tolerance);
  est.lambda_max = hi.lambda;
  est.iterations = hi.iterations;
  // Inverse iteration: 1 / lambda_min is the largest eigenvalue of K_ff^-1.
  Eigen::MatrixXd x;
  const PowerIteration lo = power_iteration(
      [&](const Eigen::VectorXd& v, Eigen::VectorXd& w) {
        solve_reduced(v, x);
        w = x.col(0);
      },
      start_min, max_iterations, tolerance);
  est.lambda_min = 1.0 / lo.lambda;
  est.condition = est.lambda_max / est.lambda_min;
  return est;
}

}  // namespace neurosim::fem
