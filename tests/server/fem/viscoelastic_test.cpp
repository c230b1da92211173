// The Prony kernel and its creep function: validation names the term; the creep function of a
// one-term kernel is the standard linear solid's closed form; for several terms J is checked
// against its definition, the Stieltjes convolution int J(t - s) dg(s) = 1, by quadrature.
#include "server/fem/material.hpp"
#include "server/fem/viscoelastic.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

namespace neurosim::fem {
namespace {

Viscoelastic kernel(std::initializer_list<PronyTerm> terms) {
  Viscoelastic v;
  v.terms = terms;
  return v;
}

std::string message_of(const Viscoelastic& v) {
  try {
    v.validate("brain.material.viscoelastic");
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return {};
}

TEST(fem_viscoelastic, ValidationNamesFieldAndTerm) {
  EXPECT_EQ(message_of(kernel({{0.5, 0.5}, {0.3, 50.0}})), "");
  EXPECT_NE(message_of(kernel({{0.5, 0.5}, {-0.1, 50.0}})).find("brain.material.viscoelastic.terms[1].g"),
            std::string::npos);
  EXPECT_NE(message_of(kernel({{0.5, 0.0}})).find("terms[0].tau_s"), std::string::npos);
  EXPECT_NE(message_of(kernel({{0.5, -1.0}})).find("terms[0].tau_s"), std::string::npos);
  EXPECT_NE(message_of(kernel({{0.5, std::numeric_limits<double>::infinity()}})).find("terms[0].tau_s"),
            std::string::npos);
  EXPECT_NE(message_of(kernel({{std::nan(""), 1.0}})).find("terms[0].g"), std::string::npos);
  EXPECT_NE(message_of(kernel({{0.6, 1.0}, {0.4, 2.0}})).find("sum to 1"), std::string::npos);
  Viscoelastic many;
  for (int i = 0; i <= Viscoelastic::kMaxTerms; ++i) many.terms.push_back({0.01, 1.0 + i});
  EXPECT_NE(message_of(many).find("at most"), std::string::npos);
  // The material checks its kernel too.
  Material m;
  m.youngs_modulus_pa = 3000.0;
  m.poisson_ratio = 0.45;
  m.name = "brain";
  m.viscoelastic = kernel({{1.2, 1.0}});
  EXPECT_THROW(m.validate(), std::invalid_argument);
}

TEST(fem_viscoelastic, RelaxationFunction) {
  const auto v = kernel({{0.5, 0.5}, {0.3, 50.0}});
  EXPECT_DOUBLE_EQ(v.relaxation(0.0), 1.0);
  EXPECT_NEAR(v.relaxed_fraction(), 0.2, 1e-15);
  EXPECT_NEAR(v.relaxation(1e6), 0.2, 1e-15);
  EXPECT_NEAR(v.relaxation(0.5), 0.2 + 0.5 * std::exp(-1.0) + 0.3 * std::exp(-0.01), 1e-15);
}

// Standard linear solid: g = g_inf + g1 e^{-t/tau} gives J = 1/g_inf - (g1/g_inf) e^{-t g_inf/tau}.
TEST(fem_viscoelastic, OneTermCreepIsTheStandardLinearSolid) {
  const double g1 = 0.7, tau = 0.5, g_inf = 1.0 - g1;
  const auto c = creep_spectrum(kernel({{g1, tau}}));
  ASSERT_EQ(c.terms.size(), 1u);
  EXPECT_NEAR(c.terms[0].rho_s, tau / g_inf, 1e-12 * tau / g_inf);
  EXPECT_NEAR(c.terms[0].a, g1 / g_inf, 1e-12);
  EXPECT_NEAR(c.relaxed_compliance, 1.0 / g_inf, 1e-15);
  for (double t : {0.0, 0.1, 1.0, 10.0})
    EXPECT_NEAR(c.creep(t), 1.0 / g_inf - (g1 / g_inf) * std::exp(-t * g_inf / tau), 1e-12);
}

// int_0^t J(t - s) dg(s) = J(t) g(0) + int_0^t J(t - s) g'(s) ds = 1 for every t (Simpson).
TEST(fem_viscoelastic, CreepInvertsRelaxation) {
  for (const auto& v : {kernel({{0.5, 0.5}, {0.3, 50.0}}), kernel({{0.2, 0.01}, {0.2, 1.0}, {0.3, 100.0}}),
                        kernel({{0.4, 1e-3}, {0.4, 1e3}}), kernel({{0.3, 2.0}, {0.3, 2.0}})}) {
    const auto c = creep_spectrum(v);
    EXPECT_NEAR(c.creep(0.0), 1.0, 1e-12);
    EXPECT_NEAR(c.creep(1e9), 1.0 / v.relaxed_fraction(), 1e-9);
    for (const auto& k : c.terms) {
      EXPECT_GT(k.a, 0.0);
      EXPECT_GT(k.rho_s, 0.0);
    }
    auto dg = [&](double s) {
      double d = 0.0;
      for (const auto& p : v.terms) d -= p.g / p.tau_s * std::exp(-s / p.tau_s);
      return d;
    };
    double tau_min = 1e300;
    for (const auto& p : v.terms) tau_min = std::min(tau_min, p.tau_s);
    for (double t : {0.3 * tau_min, 3.0 * tau_min, 0.7, 20.0, 400.0}) {
      // Simpson on pieces graded by the relaxation times ([0, 30 tau_i] for each term, then to t).
      std::vector<double> cuts{0.0, t};
      for (const auto& p : v.terms)
        if (30.0 * p.tau_s < t) cuts.push_back(30.0 * p.tau_s);
      std::sort(cuts.begin(), cuts.end());
      double sum = 0.0;
      for (std::size_t k = 0; k + 1 < cuts.size(); ++k) {
        const int n = 20000;
        const double a = cuts[k], h = (cuts[k + 1] - a) / n;
        double part = 0.0;
        for (int i = 0; i <= n; ++i) {
          const double s = a + i * h;
          const double w = (i == 0 || i == n) ? 1.0 : (i % 2 ? 4.0 : 2.0);
          part += w * c.creep(t - s) * dg(s);
        }
        sum += part * h / 3.0;
      }
      const double conv = c.creep(t) + sum;
      EXPECT_NEAR(conv, 1.0, 1e-6) << "t = " << t;
    }
  }
}

}  // namespace
}  // namespace neurosim::fem
