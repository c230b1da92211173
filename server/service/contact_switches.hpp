// The contact options of the live physics from neurosim-server's command line
// (interaction::SimulationOptions contact_spread, contact_smooth_normals, contact_near_field;
// max_contact_nodes_per_tool, lcp_max_iterations; interaction_bench's --barycentric-contact and
// --contact-spread), so the server, and
// latency_bench through it, can run the rows other than the library's defaults and their share of
// the step be measured. Unset switches keep the library's defaults; switches that contradict
// each other (or that the library would refuse at build) are refused before anything is built.
#pragma once

#include "server/interaction/simulation.hpp"

#include <optional>
#include <string>

namespace neurosim::service {

struct ContactSwitches {
  // --barycentric-contact: contact_spread 0, no smooth normals, no near field (the rows before
  // the spread: a point's barycentric weights on its triangle).
  bool barycentric{false};
  std::optional<double> spread;          // --contact-spread, dimensionless, [0, 4]
  std::optional<bool> smooth_normals;    // --contact-smooth-normals on|off
  std::optional<bool> near_field;        // --contact-near-field on|off
  // --contact-max-rows N: max_contact_nodes_per_tool, [1, 100000] (a patch of cells much finer
  // than the tip has hundreds of rows; the default keeps the deepest 32 and counts the rest in
  // SimStatus.steps_with_rows_dropped).
  std::optional<int> max_rows;
  // --lcp-max-iterations N: lcp_max_iterations, [1, 1000000] (about one pivot per active row).
  std::optional<int> lcp_max_iterations;

  bool any() const {
    return barycentric || spread || smooth_normals || near_field || max_rows || lcp_max_iterations;
  }
  // Throws std::invalid_argument naming the switches that contradict each other, or the one
  // out of range; the message is written for the command line.
  void validate() const;
  // The given switches onto `o` (validate() first); the others keep o's values.
  void apply(interaction::SimulationOptions& o) const;
  // The options `o` ends up with, for the start-up log: "contact_spread 0, smooth normals off,
  // near field off (--barycentric-contact)" or "... (the library's defaults)".
  std::string describe() const;
};

}  // namespace neurosim::service
