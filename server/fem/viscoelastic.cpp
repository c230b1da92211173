#include "server/fem/viscoelastic.hpp"

#include <algorithm>
#include <cmath>

namespace neurosim::fem {

double Viscoelastic::relaxation(double t_s) const {
  double g = relaxed_fraction();
  for (const auto& t : terms) g += t.g * std::exp(-t_s / t.tau_s);
  return g;
}

double CreepSpectrum::creep(double t_s) const {
  double j = 1.0;
  for (const auto& k : terms) j -= k.a * std::expm1(-t_s / k.rho_s);
  return j;
}

CreepSpectrum creep_spectrum(const Viscoelastic& v) {
  v.validate("viscoelastic");
  // Terms with g > 0, equal relaxation times merged, slowest first (poles x = 1 / tau ascending).
  std::vector<PronyTerm> t;
  for (const auto& p : v.terms)
    if (p.g > 0.0) t.push_back(p);
  std::sort(t.begin(), t.end(), [](const PronyTerm& a, const PronyTerm& b) { return a.tau_s > b.tau_s; });
  std::vector<PronyTerm> merged;
  for (const auto& p : t) {
    if (!merged.empty() && merged.back().tau_s == p.tau_s) merged.back().g += p.g;
    else merged.push_back(p);
  }
  const double g_inf = v.relaxed_fraction();
  CreepSpectrum out;
  out.relaxed_compliance = 1.0 / g_inf;
  // With x = -s: phi(x) = s g^(s) = g_inf - sum g_i x tau_i / (1 - x tau_i). phi(0) = g_inf > 0
  // and phi goes from +inf just above each pole 1 / tau_i to -inf just below the next: one zero
  // in (0, 1 / tau_1) and one between consecutive poles.
  auto phi = [&](double x) {
    double f = g_inf;
    for (const auto& p : merged) f -= p.g * x * p.tau_s / (1.0 - x * p.tau_s);
    return f;
  };
  for (std::size_t k = 0; k < merged.size(); ++k) {
    double lo = k == 0 ? 0.0 : 1.0 / merged[k - 1].tau_s;
    double hi = 1.0 / merged[k].tau_s;
    for (int it = 0; it < 200 && hi - lo > 0.0; ++it) {
      const double mid = 0.5 * (lo + hi);
      if (mid <= lo || mid >= hi) break;
      (phi(mid) > 0.0 ? lo : hi) = mid;
    }
    const double x = 0.5 * (lo + hi);
    // Residue of 1 / (s phi(s)) at s = -x: 1 / (s phi'(s)), phi'(s) = sum g_i tau_i / (1 + s tau_i)^2.
    double dphi = 0.0;
    for (const auto& p : merged) {
      const double d = 1.0 - x * p.tau_s;
      dphi += p.g * p.tau_s / (d * d);
    }
    out.terms.push_back(CreepTerm{1.0 / (x * dphi), 1.0 / x});
  }
  return out;
}

}  // namespace neurosim::fem
