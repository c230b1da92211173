#include "server/fem/factor_ordering.hpp"

#include <cholmod.h>

#include <algorithm>
#include <stdexcept>
#include <unordered_map>

namespace neurosim::fem {

namespace {

// A CHOLMOD view of a compressed column-major matrix (lower triangle: stype -1).
cholmod_sparse lower_view(const SparseMatrix& a, bool pattern_only) {
  cholmod_sparse s{};
  s.nrow = static_cast<std::size_t>(a.rows());
  s.ncol = static_cast<std::size_t>(a.cols());
  s.nzmax = static_cast<std::size_t>(a.nonZeros());
  s.p = const_cast<int*>(a.outerIndexPtr());
  s.i = const_cast<int*>(a.innerIndexPtr());
  s.x = pattern_only ? nullptr : const_cast<double*>(a.valuePtr());
  s.stype = -1;
  s.itype = CHOLMOD_INT;
  s.xtype = pattern_only ? CHOLMOD_PATTERN : CHOLMOD_REAL;
  s.dtype = CHOLMOD_DOUBLE;
  s.sorted = 1;
  s.packed = 1;
  return s;
}

// The rows of `lower` ordered by METIS nested dissection of the graph of their nodes; false when
// CHOLMOD's METIS failed.
bool node_metis_order(const SparseMatrix& lower, const std::vector<int>& node_of,
                      cholmod_common& c, std::vector<int>& perm) {
  const int n = static_cast<int>(lower.rows());
  // Nodes numbered 0..g-1 in order of their first row; each node's rows in ascending order.
  std::vector<int> group(n);
  std::unordered_map<int, int> index;
  std::vector<int> first_row;
  for (int r = 0; r < n; ++r) {
    const int key = node_of.empty() ? r : node_of[static_cast<std::size_t>(r)];
    const auto it = index.emplace(key, static_cast<int>(first_row.size())).first;
    if (it->second == static_cast<int>(first_row.size())) first_row.push_back(r);
    group[r] = it->second;
  }
  const int g = static_cast<int>(first_row.size());
  std::vector<int> start(g + 1, 0), rows(n);
  for (int r = 0; r < n; ++r) ++start[group[r] + 1];
  for (int k = 0; k < g; ++k) start[k + 1] += start[k];
  {
    std::vector<int> fill(start.begin(), start.end() - 1);
    for (int r = 0; r < n; ++r) rows[fill[group[r]]++] = r;
  }
  // The node graph's lower triangle (pattern): an edge where any row pair of two nodes couples.
  std::vector<Eigen::Triplet<double, int>> edges;
  edges.reserve(static_cast<std::size_t>(lower.nonZeros()) / 4 + static_cast<std::size_t>(g));
  for (int j = 0; j < n; ++j) {
    for (SparseMatrix::InnerIterator it(lower, j); it; ++it) {
      const int a = group[static_cast<int>(it.row())], b = group[j];
      if (a != b) edges.emplace_back(std::max(a, b), std::min(a, b), 1.0);
    }
  }
  for (int k = 0; k < g; ++k) edges.emplace_back(k, k, 1.0);
  SparseMatrix graph(g, g);
  graph.setFromTriplets(edges.begin(), edges.end(), [](double x, double) { return x; });
  graph.makeCompressed();
  cholmod_sparse view = lower_view(graph, true);
  std::vector<int> node_perm(static_cast<std::size_t>(g));
  if (!cholmod_metis(&view, nullptr, 0, 0, node_perm.data(), &c)) return false;
  perm.clear();
  perm.reserve(static_cast<std::size_t>(n));
  for (int k : node_perm)
    for (int p = start[k]; p < start[k + 1]; ++p) perm.push_back(rows[p]);
  return true;
}

}  // namespace

const char* ordering_name(FactorOrdering ordering) {
  switch (ordering) {
    case FactorOrdering::kCholmodDefault: return "cholmod";
    case FactorOrdering::kAmd: return "amd";
    case FactorOrdering::kMetis: return "metis";
    case FactorOrdering::kNesdis: return "nesdis";
    case FactorOrdering::kNodeMetis: return "node-metis";
  }
  return "?";
}

FactorOrdering ordering_from_name(const std::string& name) {
  for (FactorOrdering o : {FactorOrdering::kCholmodDefault, FactorOrdering::kAmd, FactorOrdering::kMetis,
                           FactorOrdering::kNesdis, FactorOrdering::kNodeMetis})
    if (name == ordering_name(o)) return o;
  throw std::invalid_argument("unknown factor ordering '" + name +
                              "' (cholmod, amd, metis, nesdis, node-metis)");
}

cholmod_factor* analyze_ordered(const SparseMatrix& lower, FactorOrdering ordering,
                                const std::vector<int>& node_of, cholmod_common& c) {
  if (!node_of.empty() && node_of.size() != static_cast<std::size_t>(lower.rows()))
    throw std::invalid_argument("analyze_ordered: node_of has " + std::to_string(node_of.size()) +
                                " entries for " + std::to_string(lower.rows()) + " rows");
  cholmod_sparse a = lower_view(lower, false);
  // The ordering settings, restored on return (the caller's common may analyse again).
  const int nmethods = c.nmethods, method0 = c.method[0].ordering;
  struct Restore {
    cholmod_common& c;
    int nmethods, method0;
    ~Restore() {
      c.nmethods = nmethods;
      c.method[0].ordering = method0;
    }
  } restore{c, nmethods, method0};
  switch (ordering) {
    case FactorOrdering::kCholmodDefault:
      c.nmethods = 0;
      return cholmod_analyze(&a, &c);
    case FactorOrdering::kAmd:
    case FactorOrdering::kMetis:
    case FactorOrdering::kNesdis:
      c.nmethods = 1;
      c.method[0].ordering = ordering == FactorOrdering::kAmd     ? CHOLMOD_AMD
                             : ordering == FactorOrdering::kMetis ? CHOLMOD_METIS
                                                                  : CHOLMOD_NESDIS;
      return cholmod_analyze(&a, &c);
    case FactorOrdering::kNodeMetis: {
      std::vector<int> perm;
      if (!node_metis_order(lower, node_of, c, perm)) return nullptr;
      c.nmethods = 1;
      c.method[0].ordering = CHOLMOD_GIVEN;
      return cholmod_analyze_p(&a, perm.data(), nullptr, 0, &c);
    }
  }
  return nullptr;
}

}  // namespace neurosim::fem
