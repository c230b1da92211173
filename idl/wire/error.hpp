// DDS return codes → exceptions that say what was being done.
#pragma once

#include <dds/dds.h>

#include <string_view>

namespace neurosim::wire {

// Throws std::runtime_error("DDS: <what>: <dds_strretcode(rc)> (rc)").
[[noreturn]] void throw_dds_error(dds_return_t rc, std::string_view what);

// Returns rc (an entity handle or a count) when it is not an error, else throws.
inline dds_return_t check(dds_return_t rc, std::string_view what) {
  if (rc < 0) throw_dds_error(rc, what);
  return rc;
}

}  // namespace neurosim::wire
