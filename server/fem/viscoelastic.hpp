// Linear viscoelasticity with one relaxation kernel for the whole material (a Prony series) and
// its creep function. The model: the stress is the hereditary integral of the elastic stress,
//   sigma(t) = int_{-inf}^{t} g(t - s) d(D eps)(s),  g(t) = g_inf + sum_i g_i exp(-t / tau_i),
// with g(0) = 1 (the elastic constants are the instantaneous ones), g_inf = 1 - sum_i g_i > 0 the
// relaxed fraction, and a Poisson ratio that does not change with time (the bulk and the shear
// modulus relax alike). The creep function J is the inverse of g under the Stieltjes
// convolution (int J(t - s) dg(s) = 1): under a held force the displacement grows as
//   J(t) = 1 / g_inf - sum_k a_k exp(-t / rho_k),  J(0) = 1,  J(inf) = 1 / g_inf,
// with retardation times rho_k (one per relaxation time, rho_k >= tau_k) from the zeros of the
// Laplace transform s g^(s) (they interlace the poles -1 / tau_i: found by bisection to machine
// precision), and a_k its residues there.
#pragma once

#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace neurosim::fem {

// One term of the Prony series: relative modulus g (dimensionless) and relaxation time tau_s.
struct PronyTerm {
  double g{0.0};      // relative modulus g_i >= 0
  double tau_s{0.0};  // relaxation time tau_i > 0, unit s
};

// The relaxation kernel of a material. No terms: elastic (no state, no work anywhere).
struct Viscoelastic {
  static constexpr int kMaxTerms = 8;  // more terms than any published tissue fit uses

  std::vector<PronyTerm> terms;
  std::string source;  // where the values come from (citation)

  bool empty() const { return terms.empty(); }
  // Throws std::invalid_argument naming `what` and the term: g_i < 0, tau_i <= 0, a non-finite
  // value, sum g_i >= 1 (no relaxed stiffness left), more than kMaxTerms terms.
  void validate(const std::string& what) const;
  // g_inf = 1 - sum g_i (the long-time fraction of the elastic moduli).
  double relaxed_fraction() const;
  // g(t) for t >= 0 (1 at t = 0).
  double relaxation(double t_s) const;
  // Same terms (values and order): one kernel.
  bool same_kernel(const Viscoelastic& other) const;
};

// Header-only (the scene file reader validates without linking the FEM library).
inline void Viscoelastic::validate(const std::string& what) const {
  if (terms.size() > static_cast<std::size_t>(kMaxTerms)) {
    throw std::invalid_argument(what + ".terms: " + std::to_string(terms.size()) +
                                " terms, at most " + std::to_string(kMaxTerms));
  }
  double sum = 0.0;
  for (std::size_t i = 0; i < terms.size(); ++i) {
    const std::string f = what + ".terms[" + std::to_string(i) + "]";
    std::ostringstream v;
    if (!std::isfinite(terms[i].g) || terms[i].g < 0.0) {
      v << terms[i].g;
      throw std::invalid_argument(f + ".g: " + v.str() + " must be finite and >= 0");
    }
    if (!std::isfinite(terms[i].tau_s) || !(terms[i].tau_s > 0.0)) {
      v << terms[i].tau_s;
      throw std::invalid_argument(f + ".tau_s: " + v.str() + " must be finite and > 0 s");
    }
    sum += terms[i].g;
  }
  if (!(sum < 1.0)) {
    std::ostringstream v;
    v << sum;
    throw std::invalid_argument(what + ".terms: the relative moduli g sum to " + v.str() +
                                ", must be < 1 (g_inf = 1 - sum g > 0 is the relaxed stiffness)");
  }
}

inline double Viscoelastic::relaxed_fraction() const {
  double g = 1.0;
  for (const auto& t : terms) g -= t.g;
  return g;
}

inline bool Viscoelastic::same_kernel(const Viscoelastic& other) const {
  if (terms.size() != other.terms.size()) return false;
  for (std::size_t i = 0; i < terms.size(); ++i)
    if (terms[i].g != other.terms[i].g || terms[i].tau_s != other.terms[i].tau_s) return false;
  return true;
}

// One term of the creep function: J(t) = 1 + sum_k a_k (1 - exp(-t / rho_k)).
struct CreepTerm {
  double a{0.0};      // weight, dimensionless, > 0
  double rho_s{0.0};  // retardation time, unit s
};

// The creep function of a kernel (terms with equal tau merged).
struct CreepSpectrum {
  std::vector<CreepTerm> terms;
  double relaxed_compliance{1.0};  // J(inf) = 1 / g_inf = 1 + sum a_k

  // J(t) for t >= 0.
  double creep(double t_s) const;
};

// The creep function of `v` (validated). Empty terms: J = 1.
CreepSpectrum creep_spectrum(const Viscoelastic& v);

}  // namespace neurosim::fem
