// What the kernel says of a running process (/proc): its resident memory and CPU time. For
// benchmarks, soak runs, fault tests and health reports.
#pragma once

#include <sys/types.h>

namespace neurosim::common {

// Resident set size (VmRSS) of process `pid` (0: this process), unit KiB; -1 if unknown (the
// process is gone or /proc is not mounted).
long resident_kib(pid_t pid = 0);

// User + system CPU time of process `pid` (0: this process) since it started, unit s; -1 if
// unknown.
double cpu_seconds(pid_t pid = 0);

}  // namespace neurosim::common
