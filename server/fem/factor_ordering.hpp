// The fill-reducing ordering of a stiffness factor (CHOLMOD's symbolic analysis). The ordering
// sets the factor's size (nnz(L): memory, factorization flops, the cost of every solve), never
// the answer beyond round-off. For the stiffness of a 3D tetrahedral mesh, nested dissection of
// the mesh's node graph gives a smaller factor than CHOLMOD's default strategy (AMD, then METIS
// on the dof graph when AMD's fill is high): bench/RESULTS.md "The host factor's ordering".
//
//   kCholmodDefault: CHOLMOD's own strategy (nmethods = 0): AMD, then METIS on the dof graph
//                    if AMD's fill is high (flops / nnz(L) >= 500 and nnz(L) / nnz(A) >= 5), the
//                    smaller of the two;
//   kAmd, kMetis, kNesdis: that one method of CHOLMOD on the dof graph (NESDIS: CHOLMOD's nested
//                    dissection, METIS bisection and constrained minimum degree);
//   kNodeMetis:      METIS nested dissection of the node graph (the rows of one node merged: a
//                    third of the vertices, a ninth of the edges), each node's rows kept
//                    together in the order, then CHOLMOD's postorder (CHOLMOD_GIVEN).
#pragma once

#include "server/fem/assembly.hpp"

#include <string>
#include <vector>

// CHOLMOD stays out of the headers (cholmod_factor and cholmod_common are these structs).
struct cholmod_factor_struct;
struct cholmod_common_struct;

namespace neurosim::fem {

enum class FactorOrdering { kCholmodDefault, kAmd, kMetis, kNesdis, kNodeMetis };

// "cholmod", "amd", "metis", "nesdis", "node-metis".
const char* ordering_name(FactorOrdering ordering);
// The inverse; throws std::invalid_argument naming the choices.
FactorOrdering ordering_from_name(const std::string& name);

// CHOLMOD's symbolic analysis of the symmetric matrix whose lower triangle is `lower`
// (compressed, square) with `ordering`, on `common` (its supernodal and final_asis settings
// are kept; its ordering settings are restored on return). node_of: per row, the node (any
// integer label) it belongs to, for kNodeMetis (empty: every row its own node); its size must
// be lower.rows() otherwise. Returns the symbolic factor (free it with cholmod_free_factor on
// `common`), or null when CHOLMOD failed (common.status says why). Throws std::invalid_argument
// for a node_of of the wrong size.
cholmod_factor_struct* analyze_ordered(const SparseMatrix& lower, FactorOrdering ordering,
                                       const std::vector<int>& node_of,
                                       cholmod_common_struct& common);

}  // namespace neurosim::fem
