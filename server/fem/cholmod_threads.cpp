#include "server/fem/cholmod_threads.hpp"

#include <dlfcn.h>

namespace neurosim::fem {

bool cholmod_threads_follow_omp_num_threads() {
  // Looked up at run time: the OpenMP runtime is CHOLMOD's dependency, not this library's.
  using GetMaxThreads = int (*)();
  using SetMaxActiveLevels = void (*)(int);
  const auto get_max_threads =
      reinterpret_cast<GetMaxThreads>(dlsym(RTLD_DEFAULT, "omp_get_max_threads"));
  const auto set_max_active_levels =
      reinterpret_cast<SetMaxActiveLevels>(dlsym(RTLD_DEFAULT, "omp_set_max_active_levels"));
  if (!get_max_threads || !set_max_active_levels || get_max_threads() != 1) return false;
  set_max_active_levels(0);
  return true;
}

}  // namespace neurosim::fem
