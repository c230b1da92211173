# multirate_bench: the 1 kHz contact step of each elasticity tier on the bundled scenes, paced in
# real time while the tier's equilibrium is updated on its worker thread; step p50/p99, update
# rate, set-up, memory and the force error against the converged tier. `multirate_bench --csv`.
add_executable(multirate_bench ${CMAKE_CURRENT_LIST_DIR}/multirate_bench.cpp)
target_link_libraries(multirate_bench PRIVATE neurosim::interaction neurosim::scene neurosim::common neurosim_warnings)
target_compile_definitions(multirate_bench PRIVATE NEUROSIM_SOURCE_DIR="${NEUROSIM_SOURCE_DIR}")
