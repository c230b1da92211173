// Update of a dense lower Cholesky factor when a row/column of the factored matrix is dropped
// (the active-set and inactive-set LCP solvers keep their factors over the pivots this way).
#pragma once

#include <Eigen/Core>

namespace neurosim::interaction {

// Drops row/column pos of the k x k lower Cholesky factor l in place (first k-1 rows/columns
// then factor the matrix without that row and column): the rows below pos are moved up, which
// leaves one entry right of the diagonal (Hessenberg); Givens rotations of the column pairs
// (j, j+1) from the right take it out again (L Q Q^T L^T). rot_c / rot_s (k-1 entries, may be
// null) receive the rotations, for callers that apply them to other data as well.
void drop_factor_row(Eigen::MatrixXd& l, int k, int pos, double* rot_c, double* rot_s);

}  // namespace neurosim::interaction
