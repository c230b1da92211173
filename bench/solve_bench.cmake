# solve_bench: `neurosim-solve --tier nonlinear` against CalculiX (ccx, one thread) on the brain
# pressed 10 and 20 mm, same mesh (C3D4 = linear-tet), side by side. Needs neurosim-solve built.
add_executable(solve_bench ${CMAKE_CURRENT_LIST_DIR}/solve_bench.cpp)
target_link_libraries(solve_bench PRIVATE neurosim::fem neurosim::scene neurosim::common neurosim_warnings)
target_include_directories(solve_bench PRIVATE ${NEUROSIM_SOURCE_DIR})
target_compile_definitions(solve_bench PRIVATE NEUROSIM_BIN_DIR="${CMAKE_RUNTIME_OUTPUT_DIRECTORY}"
                                              NEUROSIM_SOURCE_DIR="${NEUROSIM_SOURCE_DIR}")
add_dependencies(solve_bench neurosim-solve)
