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

// Memory this process can still get, unit byte, as the system states it: the smallest of the
// machine's MemAvailable (/proc/meminfo), the address-space limit (RLIMIT_AS) less this
// process's virtual size, and its cgroup's memory.max less memory.current. +inf when none is
// known. `source` (if not null) gets which bound it is ("MemAvailable", "RLIMIT_AS", "cgroup
// memory.max").
double memory_available_bytes(const char** source = nullptr);

}  // namespace neurosim::common
