# tier_bench: cost of the elasticity tiers' static equilibrium on the bundled scenes' host meshes
# (set-up, force and tangent evaluation, one warm-started equilibrium update). `--csv` for CSV.
add_executable(tier_bench ${CMAKE_CURRENT_LIST_DIR}/tier_bench.cpp)
target_link_libraries(tier_bench PRIVATE neurosim::fem neurosim::scene neurosim::common neurosim_warnings)
target_include_directories(tier_bench PRIVATE ${NEUROSIM_SOURCE_DIR})
target_compile_definitions(tier_bench PRIVATE NEUROSIM_SOURCE_DIR="${NEUROSIM_SOURCE_DIR}")
