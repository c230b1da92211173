#include "server/interaction/inactive_set_lcp.hpp"

#include "server/interaction/cholesky_update.hpp"

#include <Eigen/Cholesky>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <stdexcept>

namespace neurosim::interaction {

namespace {

std::uint64_t column_hash(const double* p, int n) {
  std::uint64_t h = 1469598103934665603ull;
  for (int i = 0; i < n; ++i) {
    std::uint64_t b;
    std::memcpy(&b, p + i, sizeof b);
    h ^= b + 0x9e3779b97f4a7c15ull + (h << 6) + (h >> 2);
    h *= 1099511628211ull;
  }
  return h;
}

}  // namespace

void InactiveSetLcp::reserve(int max_rows) {
  if (max_rows <= capacity_) return;
  capacity_ = max_rows;
  status_.assign(capacity_, 0);
  if (ready_) size_workspace();
}

bool InactiveSetLcp::set_constant_block(const Eigen::MatrixXd& w, int rows) {
  ready_ = false;
  carry_ = false;
  constant_rows_ = 0;
  if (rows <= 0) return false;
  if (w.rows() < rows || w.cols() < rows)
    throw std::invalid_argument("InactiveSetLcp::set_constant_block: block exceeds the matrix");
  const Eigen::MatrixXd s = w.topLeftCorner(rows, rows);
  if (!s.allFinite()) return false;
  Eigen::LLT<Eigen::MatrixXd> llt(s);
  if (llt.info() != Eigen::Success) return false;
  const Eigen::MatrixXd l = llt.matrixL();
  for (int i = 0; i < rows; ++i)
    if (!(l(i, i) * l(i, i) > 1e-12 * s(i, i))) return false;
  // G = L^-T L^-1 by column blocks, using the zeros of L^-1 (lower triangular): X = L^-1 in
  // n^3/3 flops, the lower half of X^T X in 2 n^3/3 (instead of two full solves, 2 n^3).
  const int n = rows, nb_max = 128;
  Eigen::MatrixXd x = Eigen::MatrixXd::Zero(n, n);
  for (int j0 = 0; j0 < n; j0 += nb_max) {
    const int nb = std::min(nb_max, n - j0);
    auto blk = x.block(j0, j0, n - j0, nb);
    blk.topRows(nb).setIdentity();
    l.bottomRightCorner(n - j0, n - j0).triangularView<Eigen::Lower>().solveInPlace(blk);
  }
  g_.setZero(n, n);
  for (int j0 = 0; j0 < n; j0 += nb_max) {
    const int nb = std::min(nb_max, n - j0);
    g_.block(j0, j0, n - j0, nb).noalias() =
        x.bottomRightCorner(n - j0, n - j0).transpose() * x.block(j0, j0, n - j0, nb);
  }
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < j; ++i) g_(i, j) = g_(j, i);
  // The inverse replaces the factor in every solve: check it (S G x = x for a few x).
  for (int t = 0; t < 3; ++t) {
    Eigen::VectorXd probe(rows);
    for (int i = 0; i < rows; ++i) probe[i] = std::sin(1.0 + 0.7 * i + 1.3 * t);
    const Eigen::VectorXd r = s * (g_ * probe) - probe;
    if (!(r.norm() <= 1e-6 * probe.norm())) return false;
  }
  constant_rows_ = rows;
  ready_ = true;
  ds_.setConstant(rows, std::numeric_limits<double>::quiet_NaN());
  a_.setZero(rows);
  inact_.assign(rows, 0);
  li_.setZero(rows, rows);
  xs_.setZero(rows);
  wrow_.setZero(rows);
  ys_.setZero(rows);
  gs_.setZero(rows);
  rot_c_.setZero(rows);
  rot_s_.setZero(rows);
  flips_.reserve(rows + 1);
  size_workspace();
  return true;
}

void InactiveSetLcp::size_workspace() {
  const int ns = constant_rows_;
  trailing_cap_ = std::max(0, capacity_ - ns);
  const int cap = std::max(trailing_cap_, 1);
  const int entries = std::max(64, 16 * cap);
  zx_.setZero(ns, cap + 1);
  cc_.setZero(ns, entries);
  uc_.setZero(ns, entries);
  chash_.assign(entries, 0);
  cstamp_.assign(entries, -1);
  const int term_entries = std::max(32, 4 * cap);
  tg_.setZero(ns, 3 * term_entries);
  tkey_.assign(term_entries, 0);
  tblock_.assign(term_entries, nullptr);
  toffset_.assign(term_entries, 0);
  tlength_.assign(term_entries, 0);
  tstamp_.assign(term_entries, -1);
  ur_.setZero(ns, cap);
  centry_.assign(cap, -1);
  miss_.reserve(cap);
  h_.setZero(cap, cap);
  kl_.setZero(cap, cap);
  act_.assign(cap, 0);
  e_.setZero(cap);
  l_.setZero(cap);
  zrow_.setZero(cap + 1);
  columns_.setZero(std::max(capacity_, cap), cap);  // stride: capacity (fixes the dot rounding)
  wanted_.assign(cap, 0);
  if (static_cast<int>(status_.size()) < capacity_) status_.assign(capacity_, 0);
  carry_ = false;
}

bool InactiveSetLcp::refactor_inactive() {
  const int m = m_;
  for (int q = 0; q < m; ++q)
    for (int p = q; p < m; ++p) li_(p, q) = g_(inact_[p], inact_[q]);
  if (m > 0) {
    Eigen::Ref<Eigen::MatrixXd> block = li_.topLeftCorner(m, m);
    Eigen::LLT<Eigen::Ref<Eigen::MatrixXd>, Eigen::Lower> llt(block);  // in place
    if (llt.info() != Eigen::Success) return false;
  }
  auto v = zx_.col(0).head(m);
  for (int q = 0; q < m; ++q) v[q] = a_[inact_[q]];
  li_.topLeftCorner(m, m).triangularView<Eigen::Lower>().solveInPlace(v);
  return true;
}

bool InactiveSetLcp::append_inactive(int row) {
  const int m = m_;
  // New factor row: L y = G_I,row, d = G_row,row - |y|^2; Z's new row from the same y.
  auto y = gs_.head(m);
  for (int q = 0; q < m; ++q) y[q] = g_(inact_[q], row);
  li_.topLeftCorner(m, m).triangularView<Eigen::Lower>().solveInPlace(y);
  const double d = g_(row, row) - y.squaredNorm();
  if (!(d > 1e-12 * g_(row, row))) return false;
  const double ljj = std::sqrt(d);
  li_.row(m).head(m) = y.transpose();
  li_(m, m) = ljj;
  const int cols = 1 + trailing_cap_;
  auto zr = zrow_.head(cols);
  zr.noalias() = zx_.topLeftCorner(m, cols).transpose() * y;
  zx_(m, 0) = (a_[row] - zr[0]) / ljj;
  for (int c = 1; c < cols; ++c) zx_(m, c) = c - 1 < nc_ ? (ur_(row, c - 1) - zr[c]) / ljj : 0.0;
  inact_[m] = row;
  m_ = m + 1;
  return true;
}

void InactiveSetLcp::remove_inactive(int pos) {
  const int k = m_;
  // As remove_position; the column rotations of L act on the rows of Z (L Z = U_I stays true).
  for (int i = pos; i + 1 < k; ++i) inact_[i] = inact_[i + 1];
  drop_factor_row(li_, k, pos, rot_c_.data(), rot_s_.data());
  const int cols = 1 + trailing_cap_;
  for (int col = 0; col < cols; ++col) {
    double* z = &zx_(0, col);
    for (int j = pos; j + 1 < k; ++j) {
      const double x = z[j], yv = z[j + 1];
      z[j] = rot_c_[j] * x + rot_s_[j] * yv;
      z[j + 1] = -rot_s_[j] * x + rot_c_[j] * yv;
    }
  }
  m_ = k - 1;
}

int InactiveSetLcp::term_entry(const LcpColumnTerm& term) {
  const int entries = static_cast<int>(tkey_.size());
  int found = -1;
  for (int e = 0; e < entries && found < 0; ++e) {
    if (tstamp_[e] >= 0 && tkey_[e] == term.key && tblock_[e] == term.block &&
        toffset_[e] == term.offset && tlength_[e] == term.length)
      found = e;
  }
  if (found < 0) {
    long long oldest = solve_count_ + 1;
    for (int e = 0; e < entries; ++e) {
      if (tstamp_[e] < oldest) {
        oldest = tstamp_[e];
        found = e;
      }
    }
    tkey_[found] = term.key;
    tblock_[found] = term.block;
    toffset_[found] = term.offset;
    tlength_[found] = term.length;
    const Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, 3>> b(term.block, term.length, 3);
    tg_.middleCols(3 * found, 3).noalias() = g_.middleCols(term.offset, term.length) * b;
  }
  tstamp_[found] = solve_count_;
  return found;
}

void InactiveSetLcp::trailing_columns(const LcpProblem& problem) {
  const Eigen::MatrixXd& w = *problem.compliance;
  const int ns = constant_rows_, nc = problem.rows - ns;
  if (problem.column_terms != nullptr && problem.terms_per_row > 0) {
    // U_r = sum over the row's terms of (G B) coef.
    const std::vector<LcpColumnTerm>& terms = *problem.column_terms;
    const int per_row = problem.terms_per_row;
    if (static_cast<int>(terms.size()) < per_row * nc)
      throw std::invalid_argument("InactiveSetLcp::solve: fewer column terms than trailing rows");
    for (int r = 0; r < nc; ++r) {
      auto u = ur_.col(r);
      u.setZero();
      for (int k = 0; k < per_row; ++k) {
        const LcpColumnTerm& t = terms[static_cast<std::size_t>(r * per_row + k)];
        if (t.block == nullptr || t.length == 0) continue;
        if (t.offset < 0 || t.length < 0 || t.offset + t.length > ns)
          throw std::invalid_argument("InactiveSetLcp::solve: a column term exceeds the constant rows");
        u.noalias() += tg_.middleCols(3 * term_entry(t), 3) * t.coef;
      }
    }
    return;
  }
  // U_r = G C_r from the cache (one pass over G for all misses).
  miss_.clear();
  for (int r = 0; r < nc; ++r) {
    const double* col = &w(0, ns + r);
    const std::uint64_t h = column_hash(col, ns);
    int found = -1;
    for (int e = 0; e < static_cast<int>(chash_.size()) && found < 0; ++e) {
      if (cstamp_[e] >= 0 && chash_[e] == h &&
          std::memcmp(col, &cc_(0, e), sizeof(double) * ns) == 0)
        found = e;
    }
    if (found < 0) {
      long long oldest = solve_count_;
      for (int e = 0; e < static_cast<int>(chash_.size()); ++e) {
        if (cstamp_[e] < oldest) {
          oldest = cstamp_[e];
          found = e;
        }
      }
      chash_[found] = h;
      cc_.col(found) = w.col(ns + r).head(ns);
      uc_.col(found).setZero();
      miss_.push_back(found);
    }
    cstamp_[found] = solve_count_;
    centry_[r] = found;
  }
  for (int j = 0; j < ns && !miss_.empty(); ++j) {
    const auto gj = g_.col(j);
    for (int e : miss_) {
      const double c = cc_(j, e);
      if (c != 0.0) uc_.col(e) += c * gj;
    }
  }
  for (int r = 0; r < nc; ++r) ur_.col(r) = uc_.col(centry_[r]);
}

bool InactiveSetLcp::solve(const LcpProblem& problem, const LcpOptions& options,
                           Eigen::VectorXd& lambda, LcpResult& result) {
  const Eigen::MatrixXd& w = *problem.compliance;
  const Eigen::VectorXd& delta = *problem.depth;
  const int n = problem.rows;
  const std::vector<char>* initial_active = problem.initial_active;
  const double tolerance = options.tolerance;
  const int max_iterations = options.max_iterations;
  const int ns = constant_rows_, nc = n - ns;
  ++solve_count_;
  p_ = 0;
  result = LcpResult{};
  lambda.head(n).setZero();
  double delta_scale = 0.0;  // max |delta|, unit m: the scale of the slack tolerance
  for (int i = 0; i < n; ++i) delta_scale = std::max(delta_scale, std::abs(delta[i]));
  if (delta_scale == 0.0) {
    result.converged = true;
    return true;
  }
  // a = G d_s, only when d_s changed.
  bool new_a = false;
  for (int i = 0; i < ns && !new_a; ++i) new_a = !(ds_[i] == delta[i]);
  if (new_a) {
    ds_ = delta.head(ns);
    a_.noalias() = g_ * ds_;
    carry_ = false;
  }

  nc_ = nc;
  trailing_columns(problem);
  for (int r = 0; r < nc; ++r) {
    const auto cr = w.col(ns + r).head(ns);
    e_[r] = delta[ns + r] - cr.dot(a_);
    for (int q = 0; q <= r; ++q) {
      const double v = w(ns + r, ns + q) - cr.dot(ur_.col(q));
      h_(r, q) = v;
      h_(q, r) = v;
    }
  }

  for (int attempt = 0; attempt < 2; ++attempt) {
    const bool carry = carry_ && carried_solves_ < 1000;
    if (carry) {
      ++carried_solves_;
    } else {
      carried_solves_ = 0;
      m_ = 0;
      for (int i = 0; i < ns; ++i) {
        const bool start = initial_active ? (*initial_active)[i] != 0 : delta[i] > 0.0;
        status_[i] = start ? 1 : 0;
        if (!start) inact_[m_++] = i;
      }
      if (!refactor_inactive()) return false;
    }
    carry_ = true;
    const int m0 = m_;
    for (int r = 0; r < nc; ++r) {
      auto z = zx_.col(1 + r).head(m0);
      for (int q = 0; q < m0; ++q) z[q] = ur_(inact_[q], r);
      li_.topLeftCorner(m0, m0).triangularView<Eigen::Lower>().solveInPlace(z);
    }
    for (int r = 0; r < nc; ++r) {
      const int row = ns + r;
      const bool start = initial_active ? (*initial_active)[row] != 0 : delta[row] > 0.0;
      status_[row] = !(w(row, row) > 0.0) ? 2 : start ? 1 : 0;
    }

    const double tol_w = tolerance * delta_scale;
    bool murty = false, converged = false;
    int best = n + 1, tries = 3;
    double drift = 0.0, lambda_scale = 0.0, term_scale = 0.0;
    const double a_scale = ns > 0 ? a_.head(ns).cwiseAbs().maxCoeff() : 0.0;
    result.iterations = 0;
    for (int it = 0; it < max_iterations; ++it) {
      result.iterations = it + 1;
      const int m = m_;
      const auto v = zx_.col(0).head(m);
      // K = H + Z^T Z over the active trailing rows, factored row by row; a row whose pivot is
      // lost to round-off depends on the active rows before it: blocked.
      int p = 0;
      for (int r = 0; r < nc; ++r) {
        if (status_[ns + r] != 1) continue;
        const auto zr = zx_.col(1 + r).head(m);
        for (int b = 0; b < p; ++b) {
          double s = h_(r, act_[b]) + zr.dot(zx_.col(1 + act_[b]).head(m));
          for (int c = 0; c < b; ++c) s -= kl_(p, c) * kl_(b, c);
          kl_(p, b) = s / kl_(b, b);
        }
        double d = h_(r, r) + zr.squaredNorm();
        for (int c = 0; c < p; ++c) d -= kl_(p, c) * kl_(p, c);
        if (!(d > 1e-12 * w(ns + r, ns + r))) {
          status_[ns + r] = 2;
          result.dependent_rows = true;
          continue;
        }
        kl_(p, p) = std::sqrt(d);
        act_[p++] = r;
      }
      p_ = p;
      // K l = e_Ac + Z_Ac^T v.
      auto l = l_.head(p);
      for (int a = 0; a < p; ++a) l[a] = e_[act_[a]] + zx_.col(1 + act_[a]).head(m).dot(v);
      kl_.topLeftCorner(p, p).triangularView<Eigen::Lower>().solveInPlace(l);
      kl_.topLeftCorner(p, p).triangularView<Eigen::Lower>().transpose().solveInPlace(l);
      // w_I = L^-T (Z_Ac l - v).
      auto y = ys_.head(m);
      y = -v;
      for (int a = 0; a < p; ++a) y.noalias() += l[a] * zx_.col(1 + act_[a]).head(m);
      li_.topLeftCorner(m, m).triangularView<Eigen::Lower>().transpose().solveInPlace(y);
      // lambda_s = a - U_Ac l + G_:I w_I (zero on I up to round-off: the drift).
      // (The drift is measured against the size of the terms: lambda may be all zero.)
      auto x = xs_.head(ns);
      x.setZero();
      for (int q = 0; q < m; ++q) x.noalias() += y[q] * g_.col(inact_[q]);
      term_scale = std::max(x.cwiseAbs().maxCoeff(), a_scale);
      x += a_;
      for (int a = 0; a < p; ++a) x.noalias() -= l[a] * ur_.col(act_[a]);
      drift = 0.0;
      for (int q = 0; q < m; ++q) {
        drift = std::max(drift, std::abs(x[inact_[q]]));
        x[inact_[q]] = 0.0;
        wrow_[inact_[q]] = y[q];
      }
      lambda_scale = 0.0;
      for (int i = 0; i < ns; ++i) lambda_scale = std::max(lambda_scale, std::abs(x[i]));
      for (int a = 0; a < p; ++a) lambda_scale = std::max(lambda_scale, std::abs(l[a]));
      const double tol_l = tolerance * std::max(lambda_scale, 1e-300);
      // Sign conditions, in index order.
      flips_.clear();
      for (int i = 0; i < ns; ++i) {
        if ((status_[i] == 1 && x[i] < -tol_l) || (status_[i] == 0 && wrow_[i] < -tol_w))
          flips_.push_back(i);
      }
      for (int r = 0; r < nc; ++r) {
        const int row = ns + r;
        if (status_[row] == 1) {
          int a = 0;
          while (act_[a] != r) ++a;
          if (l[a] < -tol_l) flips_.push_back(row);
        } else if (status_[row] == 0) {
          double s = w.col(row).head(ns).dot(x) - delta[row];
          for (int a = 0; a < p; ++a) s += w(row, ns + act_[a]) * l[a];
          if (s < -tol_w) flips_.push_back(row);
        }
      }
      const int count = static_cast<int>(flips_.size());
      if (count == 0) {
        converged = true;
        break;
      }
      if (!murty) {
        if (count < best) {
          best = count;
          tries = 3;
        } else if (tries > 0) {
          --tries;
        } else {
          murty = true;
        }
      }
      const int nflip = murty ? 1 : count;  // Murty: the least index only
      // Active leading rows that leave (marked 3), then rows leaving I (positions from the back,
      // so the others keep theirs), then the marked rows join I; trailing rows just switch.
      for (int f = 0; f < nflip; ++f) {
        const int row = flips_[f];
        if (row >= ns)
          status_[row] = status_[row] == 1 ? 0 : 1;
        else if (status_[row] == 1)
          status_[row] = 3;
      }
      for (int q = m - 1; q >= 0; --q) {
        const int row = inact_[q];
        if (!std::binary_search(flips_.begin(), flips_.begin() + nflip, row)) continue;
        remove_inactive(q);
        status_[row] = 1;
      }
      for (int f = 0; f < nflip && flips_[f] < ns; ++f) {
        const int row = flips_[f];
        if (status_[row] != 3) continue;
        if (!append_inactive(row)) return false;
        status_[row] = 0;
      }
    }
    // Result: lambda, the remaining violation (slack of inactive rows exact from W).
    lambda.head(n).setZero();
    for (int i = 0; i < ns; ++i) lambda[i] = xs_[i];
    for (int a = 0; a < p_; ++a) lambda[ns + act_[a]] = l_[a];
    const double lscale = std::max(lambda_scale, 1e-300);
    double violation = drift / std::max({lambda_scale, term_scale, 1e-300});
    for (int i = 0; i < n; ++i) {
      if (lambda[i] != 0.0 || (i < ns && status_[i] == 1)) {
        violation = std::max(violation, -lambda[i] / lscale);
        if (i >= ns)
          violation =
              std::max(violation, -(w.col(i).head(n).dot(lambda.head(n)) - delta[i]) / delta_scale);
        continue;
      }
      const double wi = w.col(i).head(n).dot(lambda.head(n)) - delta[i];
      violation = std::max(violation, -wi / delta_scale);
    }
    result.max_violation = violation;
    result.converged = converged && violation <= 1e3 * tolerance && lambda.head(n).allFinite();
    if (!result.converged && converged && carry) {
      carry_ = false;  // round-off of the kept factor: once more from scratch
      result = LcpResult{};
      continue;
    }
    break;
  }
  if (!lambda.head(n).allFinite()) carry_ = false;
  result.active = 0;
  for (int i = 0; i < ns; ++i)
    if (status_[i] == 1 && lambda[i] != 0.0) ++result.active;
  for (int a = 0; a < p_; ++a)
    if (lambda[ns + act_[a]] != 0.0) ++result.active;
  return true;
}

void InactiveSetLcp::invert_active(int first_row, ActiveBlockInverse& out) {
  const int ns = constant_rows_;
  if (first_row < ns)
    throw std::logic_error("InactiveSetLcp::invert_active: the constant rows' inverse is not kept");
  // The trailing rows' block of W_AA^-1 is K^-1 = Lk^-T Lk^-1.
  int m = 0;
  for (int a = 0; a < p_; ++a)
    if (ns + act_[a] >= first_row) wanted_[m++] = a;
  for (int j = 0; j < m; ++j) {
    auto z = columns_.col(j).head(p_);
    z.setZero();
    z[wanted_[j]] = 1.0;
    kl_.topLeftCorner(p_, p_).triangularView<Eigen::Lower>().solveInPlace(z);
    out.rows[j] = ns + act_[wanted_[j]];
  }
  out.count = m;
  for (int a = 0; a < m; ++a)
    for (int b = 0; b <= a; ++b) {
      const double v = columns_.col(a).head(p_).dot(columns_.col(b).head(p_));
      out.inverse(a, b) = v;
      out.inverse(b, a) = v;
    }
}

}  // namespace neurosim::interaction
