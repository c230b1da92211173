// CHOLMOD's own threads. CHOLMOD as Debian builds it runs the copies of its supernodal
// factorization in OpenMP regions of a compiled-in 4 threads (CHOLMOD_OMP_NUM_THREADS), whatever
// OMP_NUM_THREADS says: on a loaded 2-core machine those threads cost more in wake-ups than they
// save (neurosim-solve on the 7 mm brain pressed 20 mm: 8.1 s CPU with them, 6.6 s without,
// bench/RESULTS.md "Nonlinear static solve against CalculiX").
#pragma once

namespace neurosim::fem {

// When OMP_NUM_THREADS is 1 (omp_get_max_threads() == 1), makes the calling thread's OpenMP
// regions run on that thread alone (omp_set_max_active_levels(0)), CHOLMOD's included; otherwise,
// or when no OpenMP runtime is loaded, does nothing. Per thread (the max-active-levels ICV of the
// calling thread's data environment): call it on the thread that factorizes. Returns whether it
// limited them.
bool cholmod_threads_follow_omp_num_threads();

}  // namespace neurosim::fem
