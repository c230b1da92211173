# viscoelastic_bench: the 1 kHz contact step on the bundled brain, elastic (brain_artery.scene)
# and viscoelastic (brain_viscoelastic.scene) side by side in one run; step p50/p99/max and the
# force at the end of the hold. `viscoelastic_bench --csv`.
add_executable(viscoelastic_bench ${CMAKE_CURRENT_LIST_DIR}/viscoelastic_bench.cpp)
target_link_libraries(viscoelastic_bench PRIVATE neurosim::interaction neurosim::scene neurosim::common neurosim_warnings)
target_compile_definitions(viscoelastic_bench PRIVATE NEUROSIM_SOURCE_DIR="${NEUROSIM_SOURCE_DIR}")
