#include "server/fem/equilibrium_solver.hpp"

#include "common/process_stats.hpp"
#include "server/fem/cholmod_threads.hpp"
#include "server/fem/factor_ordering.hpp"
#include "server/fem/static_solver.hpp"

#include <Eigen/Cholesky>
#include <Eigen/CholmodSupport>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <iomanip>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <utility>

namespace neurosim::fem {

namespace {

double max_abs(const Eigen::VectorXd& v) { return v.size() ? v.cwiseAbs().maxCoeff() : 0.0; }

struct Failure : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Eigen's supernodal LL^T with access to CHOLMOD's factor and common: cholmod_solve2 reuses its
// workspace from solve to solve (Eigen's solve() allocates the result and CHOLMOD's scratch at
// every call, which the chord iterations of reuse_factorization would do dozens of times).
class SupernodalFactor : public Eigen::CholmodSupernodalLLT<SparseMatrix, Eigen::Lower> {
 public:
  cholmod_factor* factor() const { return this->m_cholmodFactor; }
  cholmod_common& common() { return this->cholmod(); }
  // Takes a symbolic factor made by analyze_ordered as if analyzePattern had made it.
  void adopt_analysis(cholmod_factor* f) {
    if (this->m_cholmodFactor) cholmod_free_factor(&this->m_cholmodFactor, &common());
    this->m_cholmodFactor = f;
    this->m_isInitialized = true;
    this->m_info = f != nullptr ? Eigen::Success : Eigen::NumericalIssue;
    this->m_analysisIsOk = f != nullptr;
    this->m_factorizationIsOk = false;
  }
  // Exchanges the factors of two objects of the same analysis (each stays freed by its own
  // common: the default allocator, so either common may free either factor).
  void swap_factor(SupernodalFactor& other) { std::swap(this->m_cholmodFactor, other.m_cholmodFactor); }
};

void check_options(const std::string& where, const NewtonOptions& o) {
  if (o.increments < 0 || !(o.tolerance > 0.0) || o.max_iterations < 1 || o.max_cutbacks < 0 ||
      o.min_iterations < 0 || o.min_iterations > o.max_iterations || o.step_limit < 0 ||
      !(o.path_tolerance >= 0.0) ||
      (o.reuse_factorization && !(o.refactor_contraction > 0.0 && o.refactor_contraction < 1.0)) ||
      (o.reuse_factorization && (o.anderson_depth < 0 || o.anderson_depth > 16))) {
    std::ostringstream msg;
    msg << where << ": bad NewtonOptions (increments " << o.increments << " >= 0, tolerance "
        << o.tolerance << " > 0, max_iterations " << o.max_iterations << " >= 1, min_iterations "
        << o.min_iterations << " in [0, max_iterations], max_cutbacks "
        << o.max_cutbacks << " >= 0, refactor_contraction " << o.refactor_contraction
        << " in (0, 1) and anderson_depth " << o.anderson_depth
        << " in [0, 16] when reuse_factorization)";
    throw std::invalid_argument(msg.str());
  }
}

}  // namespace

struct EquilibriumSolver::Impl {
  std::string where;
  FactorOrdering ordering{FactorOrdering::kNodeMetis};  // EquilibriumDefinition::ordering
  double max_factor_bytes{0.0};                          // EquilibriumDefinition::max_factor_bytes
  std::vector<ElasticForces> bodies;  // host first, then the tied meshes
  // Per body: the evaluation scratch (anp-tet, smoothed-tet), so no evaluation allocates.
  mutable std::vector<ElasticForces::Workspace> workspaces;
  std::vector<int> offset;            // per body: first stacked dof
  int ndof{0};                        // stacked dofs
  // Tie elimination u = T q: q holds every stacked dof except the tied ones (which follow
  // their host triangle). q index <-> stacked dof; tie_terms: (tied dof, host dof, weight).
  struct TieTerm {
    int tied_dof, host_dof;
    double weight;
  };
  std::vector<TieTerm> tie_terms;
  std::vector<int> q_dof;    // q index -> stacked dof
  std::vector<int> q_index;  // stacked dof -> q index or -1 (tied)
  SparseMatrix kq;           // T^T K T (ties present): its pattern made once, values refilled
  // T^T K T by a fixed scatter (ties present), so a tangent allocates nothing: value p of body
  // b's tangent adds into kq's value kq_direct[b][p] when its row and column are both q dofs
  // (T's weight 1), and into tie_scatter's entries otherwise (a tied row or column: the weights'
  // product, per host dof of the tied dof's triangle).
  std::vector<std::vector<int>> kq_direct;  // per body, per tangent value: kq position or -1
  struct TieScatter {
    int dst;     // kq value
    int body;    // tangent of body
    int src;     // its value
    double weight;
  };
  std::vector<TieScatter> tie_scatter;

  std::vector<int> constrained_dofs;   // q indices, ascending: fixed dofs and prescribed dofs
  Eigen::VectorXd constrained_values;  // at load factor 1, per constrained dof
  std::vector<int> prescribed_dofs;    // host dofs (expand_prescribed order)
  std::vector<int> prescribed_slot;    // per prescribed dof: index into constrained_dofs
  std::vector<int> free_dofs;          // reduced -> stacked dof
  double stiffness_force_scale{0.0};   // 1e-6 E_max h^2, unit N

  std::vector<SparseMatrix> k_body;  // per body tangent (assembler pattern)
  SparseMatrix kff;                  // lower triangle of the free block (the analysis' input)
  std::vector<int> kff_source;       // kff value p <- tangent value kff_source[p]
  // The free block permuted by the factor's ordering, lower triangle (tril(P K_ff P^T)): what
  // cholmod_super_numeric factors. Filled in place from the tangent (value q <- tangent value
  // perm_source[q]), so a factorization neither transposes nor allocates the matrix (through
  // cholmod_factorize every factorization made two permuted transposes of K_ff).
  std::vector<int> perm_outer, perm_inner, perm_source;
  std::vector<double> perm_values;
  Eigen::Index tangent_nnz{0};       // stored entries of the q-space tangent (fixed structure)
  // f_int holds the internal forces at f_int_u when f_int_known (set when Newton returns): the
  // next call, warm-started from that answer, starts without evaluating them again (one of the
  // ~6-8 force evaluations of a reused-factor update; bitwise the same numbers).
  Eigen::VectorXd f_int_u;
  bool f_int_known{false};
  bool forces_known_at(const Eigen::VectorXd& u) const {
    return f_int_known && f_int_u.size() == u.size() && f_int_u == u;
  }

  SupernodalFactor llt;
  // A numeric factorization's cost in chord steps (a back-substitution with the factor and a
  // residual), from the symbolic analysis: flops / (4 nnz(L) kSolveRateRatio), at least 1.
  // The factorization runs dense BLAS-3 kernels on the supernodes, a back-substitution streams
  // the factor once forwards and once backwards: kSolveRateRatio = 7 is the ratio of their flop
  // rates measured on the 5 mm brain's smoothed-tet tangent (151.8 GFlop in 7.3 s, 4 x 58.4 M
  // in 0.08 s: about 70 chord steps with the tangent's assembly and the residual) and about
  // that of the 7 mm brain's linear-tet one (2.5 GFlop in 0.18 s, 4 x 4.2 M in 5 ms: about 25).
  // Deterministic (the analysis' counts, not a clock): the iterates do not depend on the load.
  static constexpr double kSolveRateRatio = 7.0;
  double factor_steps{1.0};
  // The last contractions max |r_new| / max |r_old| of the steps with the current factor (logs,
  // a ring of kRateWindow): their geometric mean is the chord iteration's rate. Anderson steps
  // contract unevenly (a step of 0.6-1.0 between steps of 0.01-0.1 is common), so one step's
  // contraction misjudges it.
  static constexpr int kRateWindow = 3;
  std::array<double, kRateWindow> rate_log{};
  int rate_count{0}, rate_head{0};
  void rate_reset() { rate_count = rate_head = 0; }
  // A refactorization asked for by the last iteration of a call cut short by step_limit: the
  // next call (warm-started from that iterate) starts with it.
  bool refactor_carried{false};
  // Records a step's contraction; returns the window's geometric mean, or 0 (no verdict) while
  // the window holds only one step that decreased the residual: a call's first step is a plain
  // chord step, the Anderson steps after it often contract much better. The call's first step
  // with an earlier factor (first_chord) that increased the residual by less than
  // kFirstChordGrowth (accepted on the potential: after the load moved, at strain ~1 the chord
  // step from the old tangent may double it) is not recorded: the Anderson steps after it judge
  // the factor (counting it in their window made nearly every such call refactorize). A larger
  // growth is a verdict at once (without the bound an update of the lateral stroke failed and
  // fell back to the incremental solve from rest).
  static constexpr double kFirstChordGrowth = 2.0;
  double rate_push(double contraction, bool first_chord) {
    if (first_chord && !(contraction < 1.0) && contraction < kFirstChordGrowth) return 0.0;
    rate_log[static_cast<std::size_t>(rate_head)] = std::log(std::max(contraction, 1e-300));
    rate_head = (rate_head + 1) % kRateWindow;
    rate_count = std::min(rate_count + 1, kRateWindow);
    if (rate_count < 2 && contraction < 1.0) return 0.0;
    double sum = 0.0;
    for (int i = 0; i < rate_count; ++i) sum += rate_log[static_cast<std::size_t>(i)];
    return std::exp(sum / rate_count);
  }
  // The chord rate above which the next iteration refactorizes, at residual r (target: the
  // tolerance's, both N) after iteration `it`: n chord steps at rate rho reach the target when
  // rho^n = target / r; a refactorization costs factor_steps chord steps and is followed by
  // about two Newton steps, and the chord steps must fit in the iterations left before the
  // budget (max_iterations / 2, below). Never below opt.refactor_contraction (a cheap factor
  // keeps that threshold).
  double refactor_rate(const NewtonOptions& opt, double r, double target, int it) const {
    const double left = static_cast<double>(opt.max_iterations / 2 - (it + 1));
    const double steps = std::min(factor_steps + 2.0, left);
    if (!(r > target) || !(target > 0.0) || steps < 1.0) return opt.refactor_contraction;
    return std::max(opt.refactor_contraction, std::pow(target / r, 1.0 / steps));
  }
  // llt holds a successful factorization (of the exact or the projected tangent at some earlier
  // u): what reuse_factorization steps with. Cleared when a factorization fails.
  bool factor_valid{false};
  bool factor_projected{false};
  cholmod_dense* solve_x{nullptr};  // cholmod_solve2 result and workspace, kept across solves
  cholmod_dense* solve_y{nullptr};
  cholmod_dense* solve_e{nullptr};

  // A factorization made on another thread (start_factorization; background_refactorization):
  // the tangent at `u` assembled into its own matrices and scratch, factored into its own
  // factor (the same symbolic analysis, copied), exchanged with llt's when adopted. The thread
  // reads only what construction fixed (bodies, maps, patterns) and writes only here.
  struct Pending {
    std::thread thread;
    std::atomic<bool> done{false};
    bool ok{false}, projected{false};
    bool stale{false};  // a factorization on the caller's thread came after it was started
    SupernodalFactor llt;
    std::vector<SparseMatrix> k_body;
    SparseMatrix kq;
    std::vector<ElasticForces::Workspace> workspaces;
    std::vector<double> perm_values;
    Eigen::VectorXd u, body_u;
  };
  std::unique_ptr<Pending> pending;  // made on first use
  bool pending_running{false};       // its thread was started and not joined yet
  bool pending_refused{false};       // no room for a second factor: refactorizations in line

  // Scratch.
  Eigen::VectorXd kdc, f_int, rq, f_ext, r_free, delta, trial, step_full, body_u, body_f;

  explicit Impl(const EquilibriumDefinition& d)
      : where("EquilibriumSolver (" + std::string(tier_name(d.tier)) + ", mesh '" +
              (d.mesh ? d.mesh->source() : std::string("?")) + "')") {}
  ~Impl() {
    if (pending_running) pending->thread.join();
    for (cholmod_dense** x : {&solve_x, &solve_y, &solve_e}) {
      if (*x) cholmod_free_dense(x, &llt.common());
    }
  }
  Impl(const Impl&) = delete;
  Impl& operator=(const Impl&) = delete;

  bool tied() const { return !tie_terms.empty(); }

  double energy(const Eigen::VectorXd& u, ElasticForcesReport* report = nullptr) const {
    double e = 0.0;
    for (std::size_t b = 0; b < bodies.size(); ++b) {
      ElasticForcesReport r;
      e += bodies[b].energy(u.segment(offset[b], bodies[b].num_dofs()), report ? &r : nullptr,
                            &workspaces[b]);
      if (report) {
        report->clamped_elements += r.clamped_elements;
        report->inverted_elements += r.inverted_elements;
        report->barrier_elements += r.barrier_elements;
        report->max_strain = std::max(report->max_strain, r.max_strain);
      }
    }
    return e;
  }

  double potential(const Eigen::VectorXd& u, const Eigen::VectorXd& fext) const {
    return energy(u) - fext.dot(u);
  }

  // rq := T^T (f_int(u) - f_ext) on every stacked dof of q (tied dofs: 0). Returns max |rq|
  // over the free dofs.
  // forces_known: f_int already holds f_int(u) (the internal forces are skipped).
  double residual(const Eigen::VectorXd& u, const Eigen::VectorXd& fext,
                  bool forces_known = false) {
    if (!forces_known && bodies.size() == 1) {
      bodies[0].internal_force(u, f_int, nullptr, &workspaces[0]);  // no copy of u into body_u
    } else if (!forces_known) {
      f_int.resize(ndof);
      for (std::size_t b = 0; b < bodies.size(); ++b) {
        const int nb = bodies[b].num_dofs();
        body_u = u.segment(offset[b], nb);
        bodies[b].internal_force(body_u, body_f, nullptr, &workspaces[b]);
        f_int.segment(offset[b], nb) = body_f;
      }
    }
    rq = f_int - fext;
    for (const TieTerm& term : tie_terms) {
      rq[term.host_dof] += term.weight * rq[term.tied_dof];
    }
    for (const TieTerm& term : tie_terms) {
      rq[term.tied_dof] = 0.0;
    }
    double r = 0.0;
    for (int dof : free_dofs) {
      r = std::max(r, std::abs(rq[dof]));
    }
    if (!std::isfinite(r)) {
      throw Failure("non-finite residual");
    }
    return r;
  }

  double force_scale(const Eigen::VectorXd& fext) const {
    double s = std::max(max_abs(fext), stiffness_force_scale);
    for (int qi : constrained_dofs) {
      s = std::max(s, std::abs(rq[q_dof[qi]]));
    }
    return s;
  }

  // The tangent in q space: the host's own (nothing tied) or T^T K T.
  const SparseMatrix& tangent(const Eigen::VectorXd& u, bool project) {
    return tangent_into(u, project, k_body, kq, workspaces, body_u);
  }
  // The same into the given matrices and scratch (only those written: a background
  // factorization assembles into its own).
  const SparseMatrix& tangent_into(const Eigen::VectorXd& u, bool project,
                                   std::vector<SparseMatrix>& kb, SparseMatrix& kqv,
                                   std::vector<ElasticForces::Workspace>& ws,
                                   Eigen::VectorXd& bu) const {
    for (std::size_t b = 0; b < bodies.size(); ++b) {
      bu = u.segment(offset[b], bodies[b].num_dofs());
      bodies[b].tangent(bu, project, kb[b], nullptr, &ws[b]);
    }
    if (!tied()) {
      return kb[0];
    }
    // T^T K T into its fixed pattern (build_tie_scatter).
    double* q = kqv.valuePtr();
    std::fill_n(q, kqv.nonZeros(), 0.0);
    for (std::size_t b = 0; b < kb.size(); ++b) {
      const double* v = kb[b].valuePtr();
      const int* to = kq_direct[b].data();
      const Eigen::Index nnz = kb[b].nonZeros();
      for (Eigen::Index p = 0; p < nnz; ++p) {
        if (to[p] >= 0) q[to[p]] += v[p];
      }
    }
    for (const TieScatter& e : tie_scatter) {
      q[e.dst] += e.weight * kb[static_cast<std::size_t>(e.body)].valuePtr()[e.src];
    }
    return kqv;
  }

  // kq's pattern (the product T^T K T of the patterns, once) and the scatter of every tangent
  // value into it.
  void build_tie_scatter() {
    const int nq = static_cast<int>(q_dof.size());
    // T by rows: a q dof's row is (q index, 1); a tied dof's row its tie terms.
    std::vector<int> t_start(ndof + 1, 0);
    for (const TieTerm& term : tie_terms) ++t_start[term.tied_dof + 1];
    for (int dof = 0; dof < ndof; ++dof) t_start[dof + 1] += t_start[dof];
    std::vector<std::pair<int, double>> t_rows(tie_terms.size());
    {
      std::vector<int> next(t_start.begin(), t_start.end() - 1);
      for (const TieTerm& term : tie_terms)
        t_rows[next[term.tied_dof]++] = {q_index[term.host_dof], term.weight};
    }
    auto for_row = [&](int dof, auto&& f) {
      if (q_index[dof] >= 0) {
        f(q_index[dof], 1.0);
      } else {
        for (int k = t_start[dof]; k < t_start[dof + 1]; ++k) f(t_rows[k].first, t_rows[k].second);
      }
    };
    // The pattern: T^T K T of the bodies' patterns (structural, no value pruned).
    std::vector<Eigen::Triplet<double>> t_triplets, k_triplets;
    for (int dof = 0; dof < ndof; ++dof)
      for_row(dof, [&](int qi, double w) { t_triplets.emplace_back(dof, qi, w); });
    for (std::size_t b = 0; b < bodies.size(); ++b) {
      const SparseMatrix& pat = bodies[b].assembler().pattern();
      for (int col = 0; col < pat.outerSize(); ++col)
        for (SparseMatrix::InnerIterator it(pat, col); it; ++it)
          k_triplets.emplace_back(offset[b] + it.row(), offset[b] + col, 1.0);
    }
    SparseMatrix t(ndof, nq), k_stacked(ndof, ndof);
    t.setFromTriplets(t_triplets.begin(), t_triplets.end());
    k_stacked.setFromTriplets(k_triplets.begin(), k_triplets.end());
    kq = SparseMatrix(t.transpose() * k_stacked * t);
    kq.makeCompressed();
    auto position = [&](int i, int j) {
      const int* begin = kq.innerIndexPtr() + kq.outerIndexPtr()[j];
      const int* end = kq.innerIndexPtr() + kq.outerIndexPtr()[j + 1];
      const int* at = std::lower_bound(begin, end, i);
      if (at == end || *at != i) throw std::logic_error(where + ": T^T K T pattern lacks an entry");
      return static_cast<int>(at - kq.innerIndexPtr());
    };
    kq_direct.resize(bodies.size());
    for (std::size_t b = 0; b < bodies.size(); ++b) {
      const SparseMatrix& pat = bodies[b].assembler().pattern();
      kq_direct[b].assign(static_cast<std::size_t>(pat.nonZeros()), -1);
      for (int col = 0; col < pat.outerSize(); ++col) {
        const int cb = offset[b] + col;
        for (int p = pat.outerIndexPtr()[col]; p < pat.outerIndexPtr()[col + 1]; ++p) {
          const int ra = offset[b] + pat.innerIndexPtr()[p];
          if (q_index[ra] >= 0 && q_index[cb] >= 0) {
            kq_direct[b][static_cast<std::size_t>(p)] = position(q_index[ra], q_index[cb]);
            continue;
          }
          for_row(ra, [&](int i, double wa) {
            for_row(cb, [&](int j, double wb) {
              tie_scatter.push_back({position(i, j), static_cast<int>(b), p, wa * wb});
            });
          });
        }
      }
    }
    // In memory order of the destination, for locality.
    std::sort(tie_scatter.begin(), tie_scatter.end(),
              [](const TieScatter& x, const TieScatter& y) { return x.dst < y.dst; });
  }

  // Pattern of the free block (lower triangle) and its source positions in `k` (q space).
  void build_free_pattern(const SparseMatrix& k) {
    const int nf = static_cast<int>(free_dofs.size());
    std::vector<int> reduced_q(k.rows(), -1);
    for (int i = 0; i < nf; ++i) reduced_q[q_index[free_dofs[i]]] = i;
    std::vector<int> outer(nf + 1, 0), inner;
    tangent_nnz = k.nonZeros();
    for (int jr = 0; jr < nf; ++jr) {
      const int col = q_index[free_dofs[jr]];
      for (int p = k.outerIndexPtr()[col]; p < k.outerIndexPtr()[col + 1]; ++p) {
        const int ir = reduced_q[k.innerIndexPtr()[p]];
        if (ir >= jr) {
          inner.push_back(ir);
          kff_source.push_back(p);
        }
      }
      outer[jr + 1] = static_cast<int>(inner.size());
    }
    kff.resize(nf, nf);
    kff.resizeNonZeros(static_cast<Eigen::Index>(inner.size()));
    std::copy(outer.begin(), outer.end(), kff.outerIndexPtr());
    std::copy(inner.begin(), inner.end(), kff.innerIndexPtr());
    std::fill_n(kff.valuePtr(), inner.size(), 0.0);
    if (nf > 0) {
      llt.cholmod().print = 0;
      // Each free dof's node (stacked dofs: 3 per node, meshes after one another).
      std::vector<int> node_of(static_cast<std::size_t>(nf));
      for (int i = 0; i < nf; ++i) node_of[static_cast<std::size_t>(i)] = free_dofs[i] / 3;
      llt.adopt_analysis(analyze_ordered(kff, ordering, node_of, llt.common()));
      if (llt.info() != Eigen::Success) {
        throw std::runtime_error(where + ": CHOLMOD analysis failed");
      }
      check_factor_memory();
      const cholmod_common& c = llt.common();
      if (c.lnz > 0.0 && c.fl > 0.0)
        factor_steps = std::max(1.0, c.fl / (4.0 * c.lnz * kSolveRateRatio));
      build_permuted_pattern();
    }
  }

  // The numeric factor's size from the symbolic analysis (supernodal: every supernode's values;
  // simplicial: nnz(L); the count of StaticSolver and FactorInfo::factor_bytes) against the
  // limit: FactorTooLarge before anything of it is allocated.
  void check_factor_memory() {
    const char* source = "EquilibriumDefinition::max_factor_bytes";
    const double limit = max_factor_bytes > 0.0 ? max_factor_bytes
                                                : common::memory_available_bytes(&source);
    const cholmod_factor* l = llt.factor();
    const cholmod_common& c = llt.common();
    const double entries = l->is_super ? static_cast<double>(l->xsize) : c.lnz;
    const double needed = entries * sizeof(double) + static_cast<double>(l->ssize) * sizeof(int) +
                          3.0 * static_cast<double>(l->nsuper + 1) * sizeof(int) +
                          2.0 * static_cast<double>(l->n) * sizeof(int);
    if (needed > limit) {
      std::ostringstream msg;
      msg << where << ": the tangent's factor needs " << std::fixed << std::setprecision(1)
          << needed / 1048576.0 << " MiB (CHOLMOD's symbolic analysis: " << kff.rows()
          << " free dofs, nnz(L) " << static_cast<long long>(c.lnz) << "), more than the "
          << limit / 1048576.0 << " MiB available (" << source << ")"
          << ": refused before factoring; use a coarser mesh, the LINEAR tier or a machine with more memory";
      throw FactorTooLarge(msg.str(), needed, limit);
    }
  }

  // perm_*: the pattern of tril(P K_ff P^T) (rows sorted in each column) and its sources.
  void build_permuted_pattern() {
    const cholmod_factor* l = llt.factor();
    if (l == nullptr || !l->is_super) return;  // simplicial: cholmod_factorize (factor())
    const int nf = static_cast<int>(kff.rows());
    const int* perm = static_cast<const int*>(l->Perm);
    std::vector<int> inverse(static_cast<std::size_t>(nf));
    for (int k = 0; k < nf; ++k) inverse[static_cast<std::size_t>(perm[k])] = k;
    // Entry (i, j), i >= j, of K_ff goes to (max, min) of (inverse[i], inverse[j]).
    const Eigen::Index nnz = kff.nonZeros();
    std::vector<int> row(static_cast<std::size_t>(nnz)), col(static_cast<std::size_t>(nnz));
    perm_outer.assign(static_cast<std::size_t>(nf) + 1, 0);
    for (int j = 0; j < nf; ++j) {
      for (int p = kff.outerIndexPtr()[j]; p < kff.outerIndexPtr()[j + 1]; ++p) {
        const int a = inverse[static_cast<std::size_t>(kff.innerIndexPtr()[p])];
        const int b = inverse[static_cast<std::size_t>(j)];
        row[static_cast<std::size_t>(p)] = std::max(a, b);
        col[static_cast<std::size_t>(p)] = std::min(a, b);
        ++perm_outer[static_cast<std::size_t>(col[static_cast<std::size_t>(p)]) + 1];
      }
    }
    for (int j = 0; j < nf; ++j) perm_outer[j + 1] += perm_outer[j];
    std::vector<int> order(static_cast<std::size_t>(nnz));
    {
      std::vector<int> next(perm_outer.begin(), perm_outer.end() - 1);
      for (Eigen::Index p = 0; p < nnz; ++p)
        order[static_cast<std::size_t>(next[col[static_cast<std::size_t>(p)]]++)] = static_cast<int>(p);
    }
    perm_inner.resize(static_cast<std::size_t>(nnz));
    perm_source.resize(static_cast<std::size_t>(nnz));
    perm_values.assign(static_cast<std::size_t>(nnz), 0.0);
    for (int j = 0; j < nf; ++j) {
      auto begin = order.begin() + perm_outer[j], end = order.begin() + perm_outer[j + 1];
      std::sort(begin, end, [&](int x, int y) { return row[x] < row[y]; });
      for (auto it = begin; it != end; ++it) {
        const std::size_t q = static_cast<std::size_t>(it - order.begin());
        perm_inner[q] = row[static_cast<std::size_t>(*it)];
        perm_source[q] = kff_source[static_cast<std::size_t>(*it)];
      }
    }
  }

  // Factorizes the free block of the tangent at u; false if not positive definite.
  bool factor(const Eigen::VectorXd& u, bool project, NewtonIncrement& inc) {
    ++inc.factorizations;
    factor_valid = false;
    rate_reset();
    const SparseMatrix& k = tangent(u, project);
    // The structure of K (assembler pattern) and of T^T K T (a product of fixed structures) never
    // changes, so the free-block map and the symbolic analysis made at construction hold.
    if (k.nonZeros() != tangent_nnz) {
      throw std::logic_error(where + ": tangent structure changed after the symbolic analysis");
    }
    factor_projected = project;
    if (pending_running) pending->stale = true;  // this factor is newer than the pending one
    if (!perm_source.empty()) {
      factor_valid = numeric(k, perm_values, llt);
      return factor_valid;
    }
    const double* src = k.valuePtr();
    double* dst = kff.valuePtr();
    for (std::size_t p = 0; p < kff_source.size(); ++p) {
      dst[p] = src[kff_source[p]];
    }
    llt.factorize(kff);
    factor_valid = llt.info() == Eigen::Success;
    return factor_valid;
  }

  // Supernodal: CHOLMOD's numeric factorization of the permuted free block of the q-space
  // tangent k into f (values: the permuted block's values, filled in place); false if not
  // positive definite.
  bool numeric(const SparseMatrix& k, std::vector<double>& values, SupernodalFactor& f) const {
    {
      const double* src = k.valuePtr();
      for (std::size_t q = 0; q < perm_source.size(); ++q) values[q] = src[perm_source[q]];
      cholmod_sparse a{};
      a.nrow = a.ncol = static_cast<std::size_t>(kff.rows());
      a.nzmax = values.size();
      a.p = const_cast<int*>(perm_outer.data());  // read only
      a.i = const_cast<int*>(perm_inner.data());
      a.x = values.data();
      a.stype = -1;  // the lower triangle
      a.itype = CHOLMOD_INT;
      a.xtype = CHOLMOD_REAL;
      a.dtype = CHOLMOD_DOUBLE;
      a.sorted = 1;
      a.packed = 1;
      double beta[2] = {0.0, 0.0};
      cholmod_factor* l = f.factor();
      cholmod_common& c = f.common();
      l->minor = l->n;
      const int ok = cholmod_super_numeric(&a, nullptr, beta, l, &c);
      // Not positive definite: ok, status CHOLMOD_NOT_POSDEF and minor the failing column.
      return ok != 0 && c.status == CHOLMOD_OK && l->minor == l->n;
    }
  }

  // Starts factorizing the tangent at u on another thread (the exact one, the projected one if
  // that is not positive definite). Returns false, starting nothing, when one is running, the
  // factor is not supernodal, or a body relaxes (its tangent reads the caller's viscous step).
  bool launch(const Eigen::VectorXd& u) {
    if (pending_running || pending_refused || perm_source.empty() || u.size() != ndof) return false;
    for (const ElasticForces::Workspace& w : workspaces)
      if (w.viscous != nullptr) return false;
    if (!pending) {
      // A second factor of the tangent's size: only with room to spare (at most half of what
      // this process can still get), else the refactorizations stay in line.
      const double bytes = static_cast<double>(llt.factor()->xsize) * sizeof(double);
      if (bytes > 0.5 * common::memory_available_bytes()) {
        pending_refused = true;
        return false;
      }
      auto p = std::make_unique<Pending>();
      p->llt.cholmod().print = 0;
      p->llt.adopt_analysis(cholmod_copy_factor(llt.factor(), &p->llt.common()));
      if (p->llt.factor() == nullptr) return false;
      p->k_body.resize(bodies.size());
      p->kq = kq;
      p->workspaces.resize(bodies.size());
      p->perm_values.assign(perm_values.size(), 0.0);
      pending = std::move(p);
    }
    Pending& p = *pending;
    p.u = u;
    p.ok = p.projected = p.stale = false;
    p.done.store(false, std::memory_order_relaxed);
    p.thread = std::thread([this] {
      cholmod_threads_follow_omp_num_threads();  // as the caller's thread: no OpenMP pool of its own
      Pending& q = *pending;
      try {
        q.ok = numeric(tangent_into(q.u, false, q.k_body, q.kq, q.workspaces, q.body_u),
                       q.perm_values, q.llt);
        if (!q.ok) {
          q.projected = true;
          q.ok = numeric(tangent_into(q.u, true, q.k_body, q.kq, q.workspaces, q.body_u),
                         q.perm_values, q.llt);
        }
      } catch (...) {
        q.ok = false;
      }
      q.done.store(true, std::memory_order_release);
    });
    pending_running = true;
    return true;
  }
  bool pending_done() const {
    return pending_running && pending->done.load(std::memory_order_acquire);
  }
  // Waits for the background factorization; true when its factor is now llt's (the matrices it
  // factored now k_body / kq). A failed or stale one is dropped.
  bool adopt_pending() {
    if (!pending_running) return false;
    pending->thread.join();
    pending_running = false;
    if (!pending->ok || pending->stale) return false;
    llt.swap_factor(pending->llt);
    k_body.swap(pending->k_body);
    // SparseMatrix::swap exchanges the arrays; std::swap copied T^T K T three times (Eigen 3.4's
    // SparseMatrix has no move assignment): a quarter of a 7 mm brain update's time.
    kq.swap(pending->kq);
    rate_reset();
    factor_valid = true;
    factor_projected = pending->projected;
    return true;
  }

  // delta := K_ff^-1 r_free with the current factor (CHOLMOD's workspace reused).
  void solve_step() {
    cholmod_dense b{};
    b.nrow = b.nzmax = b.d = static_cast<std::size_t>(r_free.size());
    b.ncol = 1;
    b.x = r_free.data();
    b.xtype = CHOLMOD_REAL;
    b.dtype = CHOLMOD_DOUBLE;
    if (!cholmod_solve2(CHOLMOD_A, llt.factor(), &b, nullptr, &solve_x, nullptr, &solve_y,
                        &solve_e, &llt.common())) {
      throw std::runtime_error(where + ": CHOLMOD solve failed (status " +
                               std::to_string(llt.common().status) + ")");
    }
    delta = Eigen::Map<const Eigen::VectorXd>(static_cast<const double*>(solve_x->x),
                                              r_free.size());
  }

  // The tangent predictor (NewtonOptions::tangent_predictor): u, converged at load factor t_now
  // with f_int(u) in f_int, becomes the start of the increment to t_next (f_ext = fext_next),
  // its constrained dofs at their new values. The step u_f += K_ff^-1 (f_ext - f_int(u) -
  // K_fc dc) uses the last factorized tangent (the matrix in k_body / kq is the one factorized;
  // a factorization at u when there is none). Kept when its residual is finite and below the
  // plain start's (u with the constrained dofs moved only); returns whether it was kept.
  bool predict(Eigen::VectorXd& u, double t_now, double t_next, const Eigen::VectorXd& fext_next,
               NewtonIncrement& inc) {
    const int nf = static_cast<int>(free_dofs.size());
    const bool start_known = forces_known_at(u);
    auto plain_start = [&] { set_constrained(u, t_next); };
    if (nf == 0 || (!factor_valid && !factor(u, false, inc) && !factor(u, true, inc))) {
      plain_start();
      return false;
    }
    const SparseMatrix& k = tied() ? kq : k_body[0];
    residual(u, fext_next, start_known);  // rq = T^T (f_int(u) - f_ext(t_next))
    kdc.setZero(k.rows());
    for (std::size_t c = 0; c < constrained_dofs.size(); ++c) {
      const double dc = (t_next - t_now) * constrained_values[static_cast<Eigen::Index>(c)];
      if (dc == 0.0) continue;
      for (SparseMatrix::InnerIterator it(k, constrained_dofs[c]); it; ++it) {
        kdc[it.row()] += it.value() * dc;
      }
    }
    r_free.resize(nf);
    for (int i = 0; i < nf; ++i) {
      r_free[i] = -rq[free_dofs[i]] - kdc[q_index[free_dofs[i]]];
    }
    solve_step();
    step_full.setZero(u.size());
    for (int i = 0; i < nf; ++i) step_full[free_dofs[i]] = delta[i];
    trial = u + step_full;
    set_constrained(trial, t_next);
    plain_start();
    auto residual_or_inf = [&](const Eigen::VectorXd& v) {
      try {
        return residual(v, fext_next);
      } catch (const Failure&) {
        return std::numeric_limits<double>::infinity();
      }
    };
    const double r_plain = residual_or_inf(u);
    const double r_predicted = trial.allFinite() ? residual_or_inf(trial) : r_plain;
    if (!(r_predicted < r_plain)) {
      f_int_known = false;  // f_int belongs to the plain start or to nothing
      return false;
    }
    u.swap(trial);
    f_int_u = u;  // the last residual evaluated was the predicted start's
    f_int_known = true;
    return true;
  }

  // Tied dofs follow their host triangle.
  void enforce_ties(Eigen::VectorXd& u) const {
    for (const TieTerm& term : tie_terms) u[term.tied_dof] = 0.0;
    for (const TieTerm& term : tie_terms) u[term.tied_dof] += term.weight * u[term.host_dof];
  }

  void set_constrained(Eigen::VectorXd& u, double load_factor) const {
    for (std::size_t c = 0; c < constrained_dofs.size(); ++c) {
      u[q_dof[constrained_dofs[c]]] = load_factor * constrained_values[c];
    }
    enforce_ties(u);
  }

  // Anderson acceleration of the chord iteration (reuse_factorization): the chord map
  // u -> u + d(u), d = K_old^-1 (f_ext - f_int(u)), converges linearly at the rate of
  // |I - K_old^-1 K(u)|; where the tangent changed (the elements under a tool), that rate is
  // poor. Mixing the last steps (type-II Anderson, = GMRES preconditioned by K_old for a linear
  // problem) removes those few slow components for a few dot products per iteration.
  // Columns of the last `aa_count` iterations with the current factor (ring buffer): differences
  // of the chord steps d and of the iterates u, on the free dofs.
  Eigen::MatrixXd aa_dd, aa_du;
  Eigen::VectorXd aa_prev_d, aa_prev_step, aa_chord;
  static constexpr int kMaxAndersonDepth = 16;
  // Halvings of a chord step while a background factorization runs (alpha down to 1/16).
  static constexpr int kChordHalvings = 4;  // NewtonOptions::anderson_depth's limit
  // Least-squares system, at most 16 x 16: fixed-capacity storage, no heap per iteration.
  using SmallMatrix =
      Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxAndersonDepth, kMaxAndersonDepth>;
  using SmallVector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxAndersonDepth, 1>;
  SmallMatrix aa_gram;
  SmallVector aa_gamma, aa_rhs;
  int aa_count{0}, aa_head{0};
  bool aa_have_prev{false};

  void aa_reset() {
    aa_count = aa_head = 0;
    aa_have_prev = false;
  }

  // delta (the chord step d_k) -> the accelerated step, if it is a descent direction; records
  // d_k. Returns true if delta was changed.
  bool aa_accelerate(int depth) {
    const Eigen::Index nf = delta.size();
    if (aa_dd.rows() != nf || aa_dd.cols() != depth) {
      aa_dd.resize(nf, depth);
      aa_du.resize(nf, depth);
      aa_reset();
    }
    if (aa_have_prev) {
      aa_dd.col(aa_head) = delta - aa_prev_d;
      aa_du.col(aa_head) = aa_prev_step;
      aa_head = (aa_head + 1) % depth;
      aa_count = std::min(aa_count + 1, depth);
    }
    aa_prev_d = delta;
    aa_have_prev = true;
    if (aa_count == 0) return false;
    // gamma = argmin |d_k - dD gamma|_2 by the normal equations (at most `depth` columns; a
    // relative diagonal shift keeps nearly dependent columns from blowing gamma up).
    const int m = aa_count;
    aa_gram.resize(m, m);
    aa_rhs.resize(m);
    for (int i = 0; i < m; ++i) {
      aa_rhs[i] = aa_dd.col(i).dot(delta);
      for (int j = 0; j <= i; ++j) aa_gram(i, j) = aa_gram(j, i) = aa_dd.col(i).dot(aa_dd.col(j));
    }
    aa_gram.diagonal().array() += 1e-12 * aa_gram.diagonal().maxCoeff();
    aa_gamma = Eigen::LDLT<SmallMatrix>(aa_gram).solve(aa_rhs);
    if (!aa_gamma.allFinite()) return false;
    aa_chord = delta;
    for (int i = 0; i < m; ++i) {
      delta.noalias() -= aa_gamma[i] * (aa_du.col(i) + aa_dd.col(i));
    }
    if (!(r_free.dot(delta) > 0.0) || !delta.allFinite()) {  // not a descent direction
      delta = aa_chord;
      return false;
    }
    return true;
  }

  // Newton at fixed external load and constrained values (already in u). Throws Failure.
  // opt.reuse_factorization: chord steps with the factor in llt (whatever u it was made at),
  // Anderson-accelerated, until a step contracts the residual by less than
  // opt.refactor_contraction.
  void newton(const Eigen::VectorXd& fext, Eigen::VectorXd& u, const NewtonOptions& opt,
              NewtonIncrement& inc) {
    const int nf = static_cast<int>(free_dofs.size());
    double rnorm = residual(u, fext, forces_known_at(u));
    f_int_known = false;  // f_int follows the trials from here on
    // Potential at u, carried from step to step; NaN = not evaluated yet. The line search tests
    // the residual decrease first (the residual of an accepted trial is needed anyway) and the
    // potential only when that fails: the same steps are accepted as with the potential first,
    // without an energy evaluation per step.
    const double unknown = std::numeric_limits<double>::quiet_NaN();
    double pi_u = unknown;
    const bool background = opt.reuse_factorization && opt.background_refactorization;
    // A factorization started earlier (start_factorization, or a background one): waited for
    // when there is no factor to step with (or the caller wants deterministic iterates),
    // else taken once it is done.
    if (opt.reuse_factorization && pending_running &&
        (!factor_valid || !background || pending_done()) && adopt_pending()) {
      ++inc.adopted_factorizations;
    }
    bool refactor = !opt.reuse_factorization || !factor_valid || refactor_carried;
    refactor_carried = false;
    const bool accelerate = opt.reuse_factorization && opt.anderson_depth > 0;
    aa_reset();
    rate_reset();
    inc.residual_n.assign(1, rnorm);
    for (int it = 0;; ++it) {
      const bool converged = rnorm <= opt.tolerance * force_scale(fext);
      if (converged && it >= opt.min_iterations) {
        f_int_u = u;  // f_int, rq belong to u here
        f_int_known = true;
        return;
      }
      if (opt.step_limit > 0 && it >= opt.step_limit) {
        inc.converged = converged;
        refactor_carried = refactor && !converged && opt.reuse_factorization;
        f_int_u = u;  // f_int, rq belong to u here
        f_int_known = true;
        return;
      }
      if (it >= opt.max_iterations) {
        std::ostringstream msg;
        msg << "no convergence in " << opt.max_iterations << " iterations (residual " << rnorm
            << " N, tolerance " << opt.tolerance * force_scale(fext) << " N)";
        throw Failure(msg.str());
      }
      // A background factorization that finished: its tangent (at a recent iterate) replaces
      // the old factor from this step on.
      if (background && !refactor && pending_done() && adopt_pending()) {
        ++inc.adopted_factorizations;
        aa_reset();
      }
      r_free.resize(nf);
      for (int i = 0; i < nf; ++i) {
        r_free[i] = -rq[free_dofs[i]];
      }
      bool fresh = false;        // the factor is the tangent at this u
      bool accelerated = false;  // delta is an Anderson step (else the factor's own step)
      double slope = 0.0;
      if (!refactor) {
        // Chord step with an earlier factor: positive definite, so a descent direction unless
        // round-off says otherwise (then the Newton step below).
        solve_step();
        if (accelerate) accelerated = aa_accelerate(opt.anderson_depth);
        slope = -r_free.dot(delta);
        refactor = !(slope < 0.0) || !delta.allFinite();
      }
      if (refactor) {
        // A step with the tangent at u (exact, or projected if the exact one is not positive
        // definite or gives no descent direction).
        fresh = true;
        accelerated = false;
        aa_reset();
        if (!factor(u, false, inc) && !factor(u, true, inc)) {
          throw Failure(
              "projected tangent is singular (a part of the mesh free to move as a rigid body?)");
        }
        solve_step();
        // Directional derivative of the potential along the step: -r . delta (< 0: descent).
        slope = -r_free.dot(delta);
        if (!(slope < 0.0) && !factor_projected) {
          if (!factor(u, true, inc)) {
            throw Failure("projected tangent is singular");
          }
          solve_step();
          slope = -r_free.dot(delta);
        }
        if (accelerate) aa_accelerate(opt.anderson_depth);  // records d_k only (no history)
      }
      if (!delta.allFinite()) {
        throw Failure("non-finite Newton step");
      }
      auto expand_step = [&] {  // delta on the free dofs -> all stacked dofs, ties followed
        step_full.setZero(u.size());
        for (int i = 0; i < nf; ++i) {
          step_full[free_dofs[i]] = delta[i];
        }
        enforce_ties(step_full);
      };
      expand_step();
      double alpha = 1.0, pi = unknown, r_trial = 0.0;
      bool accepted = false;
      for (int h = 0; h < 30; ++h) {
        trial = u + alpha * step_full;
        // Accepted: a decrease of the residual (near the solution the potential is flat to
        // round-off), or Armijo on the potential.
        r_trial = residual(trial, fext);  // rq, f_int then belong to `trial`
        pi = unknown;
        accepted = r_trial < (1.0 - 1e-4 * alpha) * rnorm;
        if (!accepted) {
          if (std::isnan(pi_u)) pi_u = potential(u, fext);
          pi = potential(trial, fext);
          accepted = std::isfinite(pi) && pi <= pi_u + 1e-4 * alpha * slope;
        }
        if (accepted) break;
        if (accelerated) {
          // The mixed step failed: the factor's own step next (history restarts from it).
          delta = aa_chord;
          slope = -r_free.dot(delta);
          accelerated = false;
          aa_count = aa_head = 0;
          expand_step();
          continue;
        }
        // An old factor's step is shortened only while a background factorization is on its
        // way (a descent direction: the factor is positive definite), to keep moving instead of
        // waiting for it; else a fresh tangent is better than a short step.
        if (!fresh && !(background && pending_running && h < kChordHalvings)) break;
        alpha *= 0.5;
        ++inc.line_search_halvings;
      }
      if (!accepted && converged) {  // a step past min_iterations' demand found nothing better
        residual(u, fext);             // rq, f_int belong to u again
        f_int_u = u;
        f_int_known = true;
        return;
      }
      if (!accepted && !fresh) {
        // The old factor's step is no good here: retry this iteration with the background
        // factorization if one is running (waited for), else with a fresh tangent (rq belongs to
        // the trial now: restore it for u).
        refactor = true;
        if (background && adopt_pending()) {
          ++inc.adopted_factorizations;
          aa_reset();
          refactor = false;
        }
        --it;
        residual(u, fext);
        continue;
      }
      if (!accepted) {
        throw Failure("line search found no decrease of the potential or the residual");
      }
      if (factor_projected) ++inc.projected_iterations;
      if (accelerate) aa_prev_step = alpha * delta;
      u.swap(trial);
      pi_u = pi;
      // Refactorize at the next iteration unless the step with the (possibly old) factor was a
      // full one and the chord iteration contracts well: its rate over the last steps with this
      // factor (rate_push) against the rate at which the chord steps still left to the
      // tolerance would cost more than a factorization (refactor_rate: a chord step is about
      // 1/25 of a factorization on the 7 mm linear-tet brain, 1/70 on the 5 mm smoothed-tet one).
      const bool budget = 2 * (it + 1) >= opt.max_iterations;
      refactor = !opt.reuse_factorization || alpha < 1.0 || budget;
      if (!refactor) {
        const double target = opt.tolerance * force_scale(fext);
        // A call that step_limit cuts before two more steps would get no verdict on its
        // factor at all: its first chord step still counts (the server's 2-step updates).
        const bool first_chord = it == 0 && !fresh && (opt.step_limit <= 0 || opt.step_limit > 2);
        refactor = rate_push(r_trial / rnorm, first_chord) >
                   refactor_rate(opt, r_trial, target, it);
      }
      // Background: the tangent at the new u is factorized on another thread while the next
      // steps go on with the old factor (a step it cannot take waits for it, above).
      if (refactor && background && !budget && (pending_running || launch(u))) refactor = false;
      rnorm = r_trial;
      inc.residual_n.push_back(rnorm);
    }
  }
};

EquilibriumSolver::EquilibriumSolver(const EquilibriumDefinition& d) {
  if (!d.mesh) {
    throw std::invalid_argument("EquilibriumSolver: no mesh");
  }
  impl_ = std::make_unique<Impl>(d);
  Impl& s = *impl_;
  s.ordering = d.ordering;
  if (!(d.max_factor_bytes >= 0.0)) {
    throw std::invalid_argument(s.where + ": max_factor_bytes must be >= 0 (0: the memory available)");
  }
  s.max_factor_bytes = d.max_factor_bytes;
  s.bodies.emplace_back(*d.mesh, d.materials, d.tier);
  for (std::size_t k = 0; k < d.tied.size(); ++k) {
    if (!d.tied[k].mesh) {
      throw std::invalid_argument(s.where + ": tied[" + std::to_string(k) + "] has no mesh");
    }
    s.bodies.emplace_back(*d.tied[k].mesh, d.tied[k].materials, d.tier);
  }
  for (const ElasticForces& b : s.bodies) {
    s.offset.push_back(s.ndof);
    s.ndof += b.num_dofs();
  }
  s.k_body.resize(s.bodies.size());
  s.workspaces.resize(s.bodies.size());
  const int n = s.bodies[0].num_nodes();

  // Constrained stacked dofs: host fixed + prescribed, each tied mesh's fixed nodes.
  std::vector<char> constrained(s.ndof, 0), is_tied(s.ndof, 0);
  std::vector<double> value(s.ndof, 0.0);
  auto check_fixed = [&](const std::vector<int>& fixed, int nodes, const std::string& what) {
    std::vector<int> sorted = fixed;
    for (int v : sorted) {
      if (v < 0 || v >= nodes) {
        throw std::invalid_argument(s.where + ": " + what + "fixed node " + std::to_string(v) +
                                    " out of range [0, " + std::to_string(nodes) + ")");
      }
    }
    std::sort(sorted.begin(), sorted.end());
    sorted.erase(std::unique(sorted.begin(), sorted.end()), sorted.end());
    return sorted;
  };
  const std::vector<int> fixed = check_fixed(d.fixed_nodes, n, "");
  for (int v : fixed) {
    for (int a = 0; a < 3; ++a) constrained[3 * v + a] = 1;
  }
  const PrescribedDofList p = expand_prescribed(d.prescribed, n, fixed);
  for (std::size_t i = 0; i < p.dofs.size(); ++i) {
    constrained[p.dofs[i]] = 1;
    value[p.dofs[i]] = p.values_m[static_cast<Eigen::Index>(i)];
  }
  s.prescribed_dofs = p.dofs;
  for (std::size_t k = 0; k < d.tied.size(); ++k) {
    const TiedMeshDefinition& tm = d.tied[k];
    const std::string what = "tied[" + std::to_string(k) + "] ";
    const int nb = s.bodies[k + 1].num_nodes();
    const int off = s.offset[k + 1];
    for (int v : check_fixed(tm.fixed_nodes, nb, what)) {
      for (int a = 0; a < 3; ++a) constrained[off + 3 * v + a] = 1;
    }
    if (tm.host_nodes.size() != tm.tied_nodes.size() || tm.weights.size() != tm.tied_nodes.size()) {
      throw std::invalid_argument(s.where + ": " + what +
                                  "needs one host triangle and weights per tied node");
    }
    for (std::size_t i = 0; i < tm.tied_nodes.size(); ++i) {
      const int v = tm.tied_nodes[i];
      if (v < 0 || v >= nb || constrained[off + 3 * v] || is_tied[off + 3 * v]) {
        throw std::invalid_argument(s.where + ": " + what + "tied node " + std::to_string(v) +
                                    " out of range, fixed, or tied twice");
      }
      for (int c = 0; c < 3; ++c) {
        const int h = tm.host_nodes[i][c];
        const double w = tm.weights[i][c];
        if (h < 0 || h >= n || !std::isfinite(w)) {
          throw std::invalid_argument(s.where + ": " + what + "tied node " + std::to_string(v) +
                                      ": host node " + std::to_string(h) +
                                      " out of range or weight not finite");
        }
        for (int a = 0; a < 3; ++a) {
          s.tie_terms.push_back({off + 3 * v + a, 3 * h + a, w});
        }
      }
      for (int a = 0; a < 3; ++a) is_tied[off + 3 * v + a] = 1;
    }
  }
  s.q_index.assign(s.ndof, -1);
  for (int dof = 0; dof < s.ndof; ++dof) {
    if (is_tied[dof]) continue;
    const int qi = static_cast<int>(s.q_dof.size());
    s.q_index[dof] = qi;
    s.q_dof.push_back(dof);
    if (constrained[dof]) {
      s.constrained_dofs.push_back(qi);
    } else {
      s.free_dofs.push_back(dof);
    }
  }
  if (s.constrained_dofs.empty()) {
    throw std::invalid_argument(s.where +
                                ": no fixed node and no prescribed component: the body is free "
                                "to move as a rigid body");
  }
  s.constrained_values.resize(static_cast<Eigen::Index>(s.constrained_dofs.size()));
  for (std::size_t c = 0; c < s.constrained_dofs.size(); ++c) {
    s.constrained_values[static_cast<Eigen::Index>(c)] = value[s.q_dof[s.constrained_dofs[c]]];
  }
  for (int dof : s.prescribed_dofs) {
    s.prescribed_slot.push_back(static_cast<int>(
        std::lower_bound(s.constrained_dofs.begin(), s.constrained_dofs.end(), s.q_index[dof]) -
        s.constrained_dofs.begin()));
  }
  // Force scale of the convergence test: 1e-6 E_max h^2, h from the host's mean element volume.
  double e_max = 0.0;
  for (const Material& m : d.materials.materials) e_max = std::max(e_max, m.youngs_modulus_pa);
  const ElasticForces& host = s.bodies[0];
  const double h = std::cbrt(host.volume_m3() / static_cast<double>(host.num_tets()));
  s.stiffness_force_scale = 1e-6 * e_max * h * h;

  if (!s.tied()) {
    // q space is the host's dofs: the free block comes straight from the assembler pattern.
    s.build_free_pattern(s.bodies[0].assembler().pattern());
    return;
  }
  s.build_tie_scatter();
  s.build_free_pattern(s.tangent(Eigen::VectorXd::Zero(s.ndof), false));
}

EquilibriumSolver::~EquilibriumSolver() = default;

bool EquilibriumSolver::start_factorization(const Eigen::VectorXd& u_m) {
  if (u_m.size() != impl_->ndof || !u_m.allFinite()) {
    throw std::invalid_argument(impl_->where + ": start_factorization needs a finite u (3N)");
  }
  return impl_->launch(u_m);
}

void EquilibriumSolver::set_prescribed_values(const Eigen::VectorXd& values_m) {
  Impl& s = *impl_;
  if (values_m.size() != static_cast<Eigen::Index>(s.prescribed_dofs.size()) ||
      !values_m.allFinite()) {
    throw std::invalid_argument(s.where + ": set_prescribed_values needs " +
                                std::to_string(s.prescribed_dofs.size()) + " finite values");
  }
  for (std::size_t i = 0; i < s.prescribed_slot.size(); ++i) {
    s.constrained_values[s.prescribed_slot[i]] = values_m[static_cast<Eigen::Index>(i)];
  }
}

const std::vector<int>& EquilibriumSolver::prescribed_dofs() const { return impl_->prescribed_dofs; }
const ElasticForces& EquilibriumSolver::forces() const { return impl_->bodies[0]; }
const ElasticForces& EquilibriumSolver::body_forces(int body) const {
  return impl_->bodies.at(static_cast<std::size_t>(body));
}
void EquilibriumSolver::set_viscous_step(int body, const ViscousStep* step) {
  impl_->workspaces.at(static_cast<std::size_t>(body)).viscous = step;
  impl_->f_int_known = false;  // the internal forces are the new step's
}
int EquilibriumSolver::body_offset(int body) const {
  return impl_->offset.at(static_cast<std::size_t>(body));
}
int EquilibriumSolver::num_dofs() const { return impl_->ndof; }
Tier EquilibriumSolver::tier() const { return impl_->bodies[0].tier(); }

EquilibriumResult EquilibriumSolver::solve(const Eigen::VectorXd& forces_n,
                                           const NewtonOptions& requested) {
  Impl& s = *impl_;
  NewtonOptions options = requested;
  options.step_limit = 0;  // a load path always converges its increments
  const int ndof = s.ndof;
  if (forces_n.size() != 0 && forces_n.size() != ndof) {
    throw std::invalid_argument(s.where + ": forces have " + std::to_string(forces_n.size()) +
                                " entries, expected 0 or " + std::to_string(ndof));
  }
  if (!forces_n.allFinite()) {
    throw std::invalid_argument(s.where + ": non-finite force");
  }
  check_options(s.where, options);
  const Eigen::VectorXd f_full = forces_n.size() ? forces_n : Eigen::VectorXd::Zero(ndof);
  EquilibriumResult result;
  Eigen::VectorXd u = Eigen::VectorXd::Zero(ndof), u_try;
  double t = 0.0;
  const double initial_step = 1.0 / (options.increments > 0 ? options.increments : 4);
  double step = initial_step;
  int cutbacks = 0;
  while (t < 1.0 - 1e-12) {
    const double t_next = std::min(1.0, t + step);
    u_try = u;
    NewtonIncrement inc;
    inc.load_factor = t_next;
    inc.cutbacks = cutbacks;
    NewtonOptions increment_options = options;
    if (t_next < 1.0 && options.path_tolerance > options.tolerance)
      increment_options.tolerance = options.path_tolerance;
    try {
      s.f_ext = t_next * f_full;
      if (options.tangent_predictor) {
        inc.predicted = s.predict(u_try, t, t_next, s.f_ext, inc);
      } else {
        s.set_constrained(u_try, t_next);
      }
      s.newton(s.f_ext, u_try, increment_options, inc);
    } catch (const Failure& e) {
      if (++cutbacks > options.max_cutbacks) {
        std::ostringstream msg;
        msg << s.where << ": Newton failed at load factor " << t_next << " after "
            << options.max_cutbacks << " cutbacks (last converged load factor " << t
            << "): " << e.what();
        throw std::runtime_error(msg.str());
      }
      step *= 0.5;
      continue;
    }
    u.swap(u_try);
    t = t_next;
    const int iterations = static_cast<int>(inc.residual_n.size()) - 1;
    result.increments.push_back(std::move(inc));
    cutbacks = 0;
    if (iterations <= 6 && options.increments == 0) {
      step = std::min(initial_step, step * 1.5);  // regrow after a cutback
    }
  }
  s.f_ext = f_full;
  s.residual(u, s.f_ext, s.forces_known_at(u));
  result.force_scale_n = s.force_scale(s.f_ext);
  result.reaction_n = Eigen::VectorXd::Zero(ndof);
  for (int qi : s.constrained_dofs) {
    const int dof = s.q_dof[qi];
    result.reaction_n[dof] = s.rq[dof];
  }
  s.energy(u, &result.elements);
  result.displacement_m = std::move(u);
  return result;
}

NewtonIncrement EquilibriumSolver::solve_from(const Eigen::VectorXd& forces_n,
                                              Eigen::VectorXd& u_m, const NewtonOptions& options) {
  Impl& s = *impl_;
  const int ndof = s.ndof;
  if ((forces_n.size() != 0 && forces_n.size() != ndof) || u_m.size() != ndof ||
      !forces_n.allFinite() || !u_m.allFinite()) {
    throw std::invalid_argument(s.where + ": solve_from needs finite forces (0 or 3N) and u (3N)");
  }
  check_options(s.where, options);
  s.f_ext = forces_n.size() ? forces_n : Eigen::VectorXd::Zero(ndof);
  s.set_constrained(u_m, 1.0);
  NewtonIncrement inc;
  inc.load_factor = 1.0;
  try {
    s.newton(s.f_ext, u_m, options, inc);
  } catch (const Failure& e) {
    throw std::runtime_error(s.where + ": " + e.what());
  }
  return inc;
}

}  // namespace neurosim::fem
