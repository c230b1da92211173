#include "server/interaction/cholesky_update.hpp"

#include <algorithm>
#include <cmath>

namespace neurosim::interaction {

void drop_factor_row(Eigen::MatrixXd& l, int k, int pos, double* rot_c, double* rot_s) {
  for (int p = 0; p < k; ++p)
    for (int i = std::max(pos, p - 1); i + 1 < k; ++i) l(i, p) = l(i + 1, p);
  for (int j = pos; j + 1 < k; ++j) {
    const double a = l(j, j), b = l(j, j + 1);
    const double r = std::hypot(a, b);
    const double c = a / r, s = b / r;
    double* cj = &l(0, j);
    double* cj1 = &l(0, j + 1);
    for (int i = j; i + 1 < k; ++i) {
      const double x = cj[i], yv = cj1[i];
      cj[i] = c * x + s * yv;
      cj1[i] = -s * x + c * yv;
    }
    l(j, j + 1) = 0.0;
    if (rot_c != nullptr) {
      rot_c[j] = c;
      rot_s[j] = s;
    }
  }
}

}  // namespace neurosim::interaction
