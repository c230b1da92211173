#include "server/service/contact_switches.hpp"

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace neurosim::service {

namespace {
const char* on_off(bool b) { return b ? "on" : "off"; }
}  // namespace

void ContactSwitches::validate() const {
  if (spread && !(std::isfinite(*spread) && *spread >= 0.0 && *spread <= 4.0)) {
    std::ostringstream os;
    os << "--contact-spread " << *spread << " is outside [0, 4]";
    throw std::invalid_argument(os.str());
  }
  if (max_rows && !(*max_rows >= 1 && *max_rows <= 100000)) {
    std::ostringstream os;
    os << "--contact-max-rows " << *max_rows << " is outside [1, 100000]";
    throw std::invalid_argument(os.str());
  }
  if (lcp_max_iterations && !(*lcp_max_iterations >= 1 && *lcp_max_iterations <= 1000000)) {
    std::ostringstream os;
    os << "--lcp-max-iterations " << *lcp_max_iterations << " is outside [1, 1000000]";
    throw std::invalid_argument(os.str());
  }
  if (barycentric) {
    if (spread && *spread != 0.0) {
      std::ostringstream os;
      os << "--barycentric-contact and --contact-spread " << *spread
         << " contradict each other (--barycentric-contact is contact spread 0)";
      throw std::invalid_argument(os.str());
    }
    if (smooth_normals && *smooth_normals)
      throw std::invalid_argument(
          "--barycentric-contact and --contact-smooth-normals on contradict each other "
          "(--barycentric-contact has no smooth normals)");
    if (near_field && *near_field)
      throw std::invalid_argument(
          "--barycentric-contact and --contact-near-field on contradict each other "
          "(--barycentric-contact has no near field)");
  }
  interaction::SimulationOptions o;
  apply(o);
  // The library refuses this at build (Simulation::build); said here before anything is built.
  if (o.contact_near_field && !(o.contact_spread > 0.0))
    throw std::invalid_argument(
        "--contact-spread 0 needs --contact-near-field off (the near field is the part the "
        "spread load does not carry; it is on by default), or use --barycentric-contact");
}

void ContactSwitches::apply(interaction::SimulationOptions& o) const {
  if (barycentric) {
    o.contact_spread = 0.0;
    o.contact_smooth_normals = false;
    o.contact_near_field = false;
  }
  if (spread) o.contact_spread = *spread;
  if (smooth_normals) o.contact_smooth_normals = *smooth_normals;
  if (near_field) o.contact_near_field = *near_field;
  if (max_rows) o.max_contact_nodes_per_tool = *max_rows;
  if (lcp_max_iterations) o.lcp_max_iterations = *lcp_max_iterations;
}

std::string ContactSwitches::describe() const {
  interaction::SimulationOptions o;
  apply(o);
  std::ostringstream os;
  os << "contact spread " << o.contact_spread << ", smooth normals " << on_off(o.contact_smooth_normals)
     << ", near field " << on_off(o.contact_near_field) << ", at most "
     << o.max_contact_nodes_per_tool << " rows per tool, LCP at most " << o.lcp_max_iterations
     << " pivots";
  if (!any()) {
    os << " (the library's defaults)";
  } else {
    os << " (";
    const char* sep = "";
    if (barycentric) {
      os << "--barycentric-contact";
      sep = " ";
    }
    if (spread) {
      os << sep << "--contact-spread " << *spread;
      sep = " ";
    }
    if (smooth_normals) {
      os << sep << "--contact-smooth-normals " << on_off(*smooth_normals);
      sep = " ";
    }
    if (near_field) {
      os << sep << "--contact-near-field " << on_off(*near_field);
      sep = " ";
    }
    if (max_rows) {
      os << sep << "--contact-max-rows " << *max_rows;
      sep = " ";
    }
    if (lcp_max_iterations) os << sep << "--lcp-max-iterations " << *lcp_max_iterations;
    os << ")";
  }
  return os.str();
}

}  // namespace neurosim::service
