# four_probes_bench: the physics of latency_bench's four-station server step in one process (all
# four poses per step, K new, optionally paced); the same file builds against an older tree's
# libraries, so two builds' contact steps compare without DDS. `four_probes_bench --csv`.
add_executable(four_probes_bench ${CMAKE_CURRENT_LIST_DIR}/four_probes_bench.cpp)
target_link_libraries(four_probes_bench PRIVATE neurosim::interaction neurosim::scene neurosim::fem neurosim::common neurosim_warnings)
target_compile_definitions(four_probes_bench PRIVATE NEUROSIM_SOURCE_DIR="${NEUROSIM_SOURCE_DIR}")
