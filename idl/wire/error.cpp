#include "idl/wire/error.hpp"

#include <stdexcept>
#include <string>

namespace neurosim::wire {

void throw_dds_error(dds_return_t rc, std::string_view what) {
  throw std::runtime_error("DDS: " + std::string(what) + ": " + dds_strretcode(rc) + " (" +
                           std::to_string(rc) + ")");
}

}  // namespace neurosim::wire
