#include "server/fem/equilibrium_solver.hpp"

#include <Eigen/CholmodSupport>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <sstream>
#include <stdexcept>
#include <string>

namespace neurosim::fem {

namespace {

double max_abs(const Eigen::VectorXd& v) { return v.size() ? v.cwiseAbs().maxCoeff() : 0.0; }

struct Failure : std::runtime_error {
  using std::runtime_error::runtime_error;
};

}  // namespace

struct EquilibriumSolver::Impl {
  std::string where;
  ElasticForces forces;
  std::vector<int> constrained_dofs;  // ascending: fixed nodes' dofs and prescribed dofs
  Eigen::VectorXd constrained_values;  // at load factor 1, per constrained dof
  std::vector<int> prescribed_dofs;   // the prescribed subset (expand_prescribed order)
  std::vector<int> prescribed_slot;   // per prescribed dof: index into constrained_dofs
  std::vector<int> free_dofs;
  std::vector<int> reduced_index;
  double stiffness_force_scale{0.0};  // 1e-6 E_max h^2, unit N

  SparseMatrix k;                 // full tangent (assembler pattern)
  SparseMatrix kff;               // lower triangle of the free block
  std::vector<int> kff_source;    // kff value p <- k value kff_source[p]
  Eigen::CholmodSupernodalLLT<SparseMatrix, Eigen::Lower> llt;

  // Scratch.
  Eigen::VectorXd f_int, f_ext, r_free, delta, trial, rhs, step_full;

  Impl(const EquilibriumDefinition& d)
      : where("EquilibriumSolver (" + std::string(tier_name(d.tier)) + ", mesh '" +
              (d.mesh ? d.mesh->source() : std::string("?")) + "')"),
        forces(*d.mesh, d.materials, d.tier) {}

  double potential(const Eigen::VectorXd& u, const Eigen::VectorXd& fext) const {
    return forces.energy(u) - fext.dot(u);
  }

  // max |f_ext - f_int| over the free dofs; fills f_int.
  double residual(const Eigen::VectorXd& u, const Eigen::VectorXd& fext) {
    forces.internal_force(u, f_int);
    double r = 0.0;
    for (std::size_t i = 0; i < free_dofs.size(); ++i) {
      r = std::max(r, std::abs(fext[free_dofs[i]] - f_int[free_dofs[i]]));
    }
    if (!std::isfinite(r)) {
      throw Failure("non-finite residual");
    }
    return r;
  }

  double force_scale(const Eigen::VectorXd& fext) const {
    double s = std::max(max_abs(fext), stiffness_force_scale);
    for (int dof : constrained_dofs) {
      s = std::max(s, std::abs(f_int[dof] - fext[dof]));
    }
    return s;
  }

  // Factorizes the free block of the tangent at u; false if not positive definite.
  bool factor(const Eigen::VectorXd& u, bool project) {
    forces.tangent(u, project, k);
    const double* src = k.valuePtr();
    double* dst = kff.valuePtr();
    for (std::size_t p = 0; p < kff_source.size(); ++p) {
      dst[p] = src[kff_source[p]];
    }
    llt.factorize(kff);
    return llt.info() == Eigen::Success;
  }

  void set_constrained(Eigen::VectorXd& u, double load_factor) const {
    for (std::size_t c = 0; c < constrained_dofs.size(); ++c) {
      u[constrained_dofs[c]] = load_factor * constrained_values[c];
    }
  }

  // Newton at fixed external load and constrained values (already in u). Throws Failure.
  void newton(const Eigen::VectorXd& fext, Eigen::VectorXd& u, const NewtonOptions& opt,
              NewtonIncrement& inc) {
    const int nf = static_cast<int>(free_dofs.size());
    double rnorm = residual(u, fext);
    inc.residual_n.assign(1, rnorm);
    for (int it = 0;; ++it) {
      if (rnorm <= opt.tolerance * force_scale(fext)) {
        return;
      }
      if (it >= opt.max_iterations) {
        std::ostringstream msg;
        msg << "no convergence in " << opt.max_iterations << " iterations (residual " << rnorm
            << " N, tolerance " << opt.tolerance * force_scale(fext) << " N)";
        throw Failure(msg.str());
      }
      r_free.resize(nf);
      for (int i = 0; i < nf; ++i) {
        r_free[i] = fext[free_dofs[i]] - f_int[free_dofs[i]];
      }
      bool projected = false;
      if (!factor(u, false)) {
        projected = true;
        if (!factor(u, true)) {
          throw Failure(
              "projected tangent is singular (a part of the mesh free to move as a rigid body?)");
        }
      }
      delta = llt.solve(r_free);
      // Directional derivative of the potential along the step: -r . delta (< 0: descent).
      double slope = -r_free.dot(delta);
      if (!(slope < 0.0) && !projected) {
        projected = true;
        if (!factor(u, true)) {
          throw Failure("projected tangent is singular");
        }
        delta = llt.solve(r_free);
        slope = -r_free.dot(delta);
      }
      if (!delta.allFinite()) {
        throw Failure("non-finite Newton step");
      }
      if (projected) ++inc.projected_iterations;
      step_full.setZero(u.size());
      for (int i = 0; i < nf; ++i) {
        step_full[free_dofs[i]] = delta[i];
      }
      const double pi0 = potential(u, fext);
      double alpha = 1.0;
      bool accepted = false;
      for (int h = 0; h < 30; ++h) {
        trial = u + alpha * step_full;
        const double pi = potential(trial, fext);
        if (std::isfinite(pi) && pi <= pi0 + 1e-4 * alpha * slope) {
          accepted = true;
        } else {
          // Near the solution the potential is flat to round-off: accept a residual decrease.
          const double r_trial = residual(trial, fext);
          accepted = r_trial < (1.0 - 1e-4 * alpha) * rnorm;
        }
        if (accepted) break;
        alpha *= 0.5;
        ++inc.line_search_halvings;
      }
      if (!accepted) {
        throw Failure("line search found no decrease of the potential or the residual");
      }
      u.swap(trial);
      rnorm = residual(u, fext);
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
  const int n = s.forces.num_nodes();
  std::vector<int> fixed = d.fixed_nodes;
  for (int v : fixed) {
    if (v < 0 || v >= n) {
      throw std::invalid_argument(s.where + ": fixed node " + std::to_string(v) +
                                  " out of range [0, " + std::to_string(n) + ")");
    }
  }
  std::sort(fixed.begin(), fixed.end());
  fixed.erase(std::unique(fixed.begin(), fixed.end()), fixed.end());
  const PrescribedDofList p = expand_prescribed(d.prescribed, n, fixed);
  std::vector<double> value(3 * n, 0.0);
  std::vector<char> constrained(3 * n, 0);
  for (int v : fixed) {
    for (int a = 0; a < 3; ++a) constrained[3 * v + a] = 1;
  }
  for (std::size_t i = 0; i < p.dofs.size(); ++i) {
    constrained[p.dofs[i]] = 1;
    value[p.dofs[i]] = p.values_m[static_cast<Eigen::Index>(i)];
  }
  s.prescribed_dofs = p.dofs;
  s.reduced_index.assign(3 * n, -1);
  for (int dof = 0; dof < 3 * n; ++dof) {
    if (constrained[dof]) {
      s.constrained_dofs.push_back(dof);
    } else {
      s.reduced_index[dof] = static_cast<int>(s.free_dofs.size());
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
    s.constrained_values[static_cast<Eigen::Index>(c)] = value[s.constrained_dofs[c]];
  }
  for (int dof : s.prescribed_dofs) {
    s.prescribed_slot.push_back(static_cast<int>(
        std::lower_bound(s.constrained_dofs.begin(), s.constrained_dofs.end(), dof) -
        s.constrained_dofs.begin()));
  }
  // Force scale of the convergence test: 1e-6 E_max h^2.
  double e_max = 0.0;
  for (const Material& m : d.materials.materials) e_max = std::max(e_max, m.youngs_modulus_pa);
  {
    // Mean element volume from the rest geometry (the assembler already validated elements).
    const auto& x = d.mesh->vertices();
    double v_sum = 0.0;
    for (const auto& t : d.mesh->tets()) {
      v_sum += std::abs((x[t[1]] - x[t[0]]).cross(x[t[2]] - x[t[0]]).dot(x[t[3]] - x[t[0]])) / 6.0;
    }
    const double h = std::cbrt(v_sum / static_cast<double>(d.mesh->num_tets()));
    s.stiffness_force_scale = 1e-6 * e_max * h * h;
  }

  // Free block pattern (lower triangle) and its source positions in the full tangent.
  const SparseMatrix& pat = s.forces.assembler().pattern();
  const int nf = static_cast<int>(s.free_dofs.size());
  std::vector<int> outer(nf + 1, 0), inner;
  for (int jr = 0; jr < nf; ++jr) {
    const int col = s.free_dofs[jr];
    for (int q = pat.outerIndexPtr()[col]; q < pat.outerIndexPtr()[col + 1]; ++q) {
      const int ir = s.reduced_index[pat.innerIndexPtr()[q]];
      if (ir >= jr) {
        inner.push_back(ir);
        s.kff_source.push_back(q);
      }
    }
    outer[jr + 1] = static_cast<int>(inner.size());
  }
  s.kff.resize(nf, nf);
  s.kff.resizeNonZeros(static_cast<Eigen::Index>(inner.size()));
  std::copy(outer.begin(), outer.end(), s.kff.outerIndexPtr());
  std::copy(inner.begin(), inner.end(), s.kff.innerIndexPtr());
  std::fill_n(s.kff.valuePtr(), inner.size(), 0.0);
  if (nf > 0) {
    s.llt.cholmod().print = 0;
    s.llt.analyzePattern(s.kff);
    if (s.llt.info() != Eigen::Success) {
      throw std::runtime_error(s.where + ": CHOLMOD analysis failed");
    }
  }
}

EquilibriumSolver::~EquilibriumSolver() = default;

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
const std::vector<int>& EquilibriumSolver::free_dofs() const { return impl_->free_dofs; }
const std::vector<int>& EquilibriumSolver::reduced_index() const { return impl_->reduced_index; }
const ElasticForces& EquilibriumSolver::forces() const { return impl_->forces; }
Tier EquilibriumSolver::tier() const { return impl_->forces.tier(); }

EquilibriumResult EquilibriumSolver::solve(const Eigen::VectorXd& forces_n,
                                           const NewtonOptions& options) {
  Impl& s = *impl_;
  const int ndof = s.forces.num_dofs();
  if (forces_n.size() != 0 && forces_n.size() != ndof) {
    throw std::invalid_argument(s.where + ": forces have " + std::to_string(forces_n.size()) +
                                " entries, expected 0 or " + std::to_string(ndof));
  }
  if (!forces_n.allFinite()) {
    throw std::invalid_argument(s.where + ": non-finite force");
  }
  if (options.increments < 0 || !(options.tolerance > 0.0) || options.max_iterations < 1 ||
      options.max_cutbacks < 0) {
    throw std::invalid_argument(s.where + ": bad NewtonOptions");
  }
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
    s.set_constrained(u_try, t_next);
    NewtonIncrement inc;
    inc.load_factor = t_next;
    inc.cutbacks = cutbacks;
    try {
      s.f_ext = t_next * f_full;
      s.newton(s.f_ext, u_try, options, inc);
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
  s.residual(u, s.f_ext);
  result.force_scale_n = s.force_scale(s.f_ext);
  result.reaction_n = Eigen::VectorXd::Zero(ndof);
  for (int dof : s.constrained_dofs) {
    result.reaction_n[dof] = s.f_int[dof] - s.f_ext[dof];
  }
  s.forces.energy(u, &result.elements);
  result.displacement_m = std::move(u);
  return result;
}

NewtonIncrement EquilibriumSolver::solve_from(const Eigen::VectorXd& forces_n,
                                              Eigen::VectorXd& u_m, const NewtonOptions& options) {
  Impl& s = *impl_;
  const int ndof = s.forces.num_dofs();
  if ((forces_n.size() != 0 && forces_n.size() != ndof) || u_m.size() != ndof ||
      !forces_n.allFinite() || !u_m.allFinite()) {
    throw std::invalid_argument(s.where + ": solve_from needs finite forces (0 or 3N) and u (3N)");
  }
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
