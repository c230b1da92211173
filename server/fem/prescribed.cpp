#include "server/fem/prescribed.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace neurosim::fem {

namespace {

constexpr char kAxis[3] = {'x', 'y', 'z'};

std::string where(std::size_t k) { return "prescribed[" + std::to_string(k) + "]"; }

}  // namespace

Components parse_components(const std::string& spec) {
  if (spec.empty()) {
    throw std::invalid_argument(
        "prescribed components: empty; expected a non-empty subset of \"xyz\" (e.g. \"z\")");
  }
  Components c{false, false, false};
  for (char ch : spec) {
    const char* hit = std::find(kAxis, kAxis + 3, ch);
    if (hit == kAxis + 3) {
      throw std::invalid_argument("prescribed components \"" + spec + "\": unknown component '" +
                                  std::string(1, ch) + "'; expected a subset of \"xyz\"");
    }
    const auto a = static_cast<std::size_t>(hit - kAxis);
    if (c[a]) {
      throw std::invalid_argument("prescribed components \"" + spec + "\": component '" +
                                  std::string(1, ch) + "' given twice");
    }
    c[a] = true;
  }
  return c;
}

std::string components_string(const Components& components) {
  std::string s;
  for (std::size_t a = 0; a < 3; ++a) {
    if (components[a]) {
      s += kAxis[a];
    }
  }
  return s;
}

PrescribedDofList expand_prescribed(const std::vector<PrescribedDofs>& prescribed, int num_nodes,
                                    const std::vector<int>& fixed_nodes) {
  std::vector<char> is_fixed(static_cast<std::size_t>(std::max(num_nodes, 0)), 0);
  for (int v : fixed_nodes) {
    if (v >= 0 && v < num_nodes) {
      is_fixed[v] = 1;
    }
  }
  struct Entry {
    int dof;
    double value;
    std::size_t def;
  };
  std::vector<Entry> entries;
  for (std::size_t k = 0; k < prescribed.size(); ++k) {
    const PrescribedDofs& p = prescribed[k];
    if (p.nodes.empty()) {
      throw std::invalid_argument(where(k) + ": no node");
    }
    if (components_string(p.components).empty()) {
      throw std::invalid_argument(where(k) +
                                  ": no component prescribed (need a non-empty subset of xyz)");
    }
    for (int a = 0; a < 3; ++a) {
      if (p.components[a] && !std::isfinite(p.displacement_m[a])) {
        throw std::invalid_argument(where(k) + ": non-finite displacement in " +
                                    std::string(1, kAxis[a]));
      }
    }
    for (int v : p.nodes) {
      if (v < 0 || v >= num_nodes) {
        throw std::invalid_argument(where(k) + ": node " + std::to_string(v) +
                                    " out of range [0, " + std::to_string(num_nodes) + ")");
      }
      if (is_fixed[v]) {
        throw std::invalid_argument(where(k) + ": node " + std::to_string(v) +
                                    " is both fixed (u = 0 in x, y, z) and prescribed");
      }
      for (int a = 0; a < 3; ++a) {
        if (p.components[a]) {
          entries.push_back({3 * v + a, p.displacement_m[a], k});
        }
      }
    }
  }
  std::stable_sort(entries.begin(), entries.end(),
                   [](const Entry& l, const Entry& r) { return l.dof < r.dof; });
  PrescribedDofList out;
  std::vector<double> values;
  for (std::size_t i = 0; i < entries.size(); ++i) {
    const Entry& e = entries[i];
    if (!out.dofs.empty() && out.dofs.back() == e.dof) {
      if (e.value != values.back()) {
        // The first definition that set this dof is the earliest entry with it (stable sort).
        std::size_t first = i;
        while (first > 0 && entries[first - 1].dof == e.dof) {
          --first;
        }
        std::ostringstream msg;
        msg.precision(15);
        msg << where(e.def) << ": node " << e.dof / 3 << " component " << kAxis[e.dof % 3]
            << " prescribed twice with different values: " << values.back() << " m by "
            << where(entries[first].def) << ", " << e.value << " m here";
        throw std::invalid_argument(msg.str());
      }
      continue;
    }
    out.dofs.push_back(e.dof);
    values.push_back(e.value);
    if (out.nodes.empty() || out.nodes.back() != e.dof / 3) {
      out.nodes.push_back(e.dof / 3);
    }
  }
  out.values_m =
      Eigen::Map<const Eigen::VectorXd>(values.data(), static_cast<Eigen::Index>(values.size()));
  return out;
}

}  // namespace neurosim::fem
