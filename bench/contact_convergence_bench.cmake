# contact_convergence_bench: the same press (the 2 mm probe, 1-3 mm deep, one point of the brain)
# on brain meshes of several cell sizes (built by neurosim-model when missing): the force as the
# cells shrink, successive differences and the observed order; with --points at many fixed points
# of the dorsal surface (the order fitted over them), with --split on meshes split 1 -> 8 (the
# surface fixed: tet_split.hpp).
# `contact_convergence_bench --cell-size 7 --cell-size 5 --cell-size 4 --cell-size 3`.
add_executable(contact_convergence_bench ${CMAKE_CURRENT_LIST_DIR}/contact_convergence_bench.cpp)
target_link_libraries(contact_convergence_bench PRIVATE neurosim::interaction neurosim::scene neurosim::fem neurosim::common
                      neurosim_warnings)
target_compile_definitions(contact_convergence_bench PRIVATE NEUROSIM_BIN_DIR="${CMAKE_RUNTIME_OUTPUT_DIRECTORY}"
                                                            NEUROSIM_SOURCE_DIR="${NEUROSIM_SOURCE_DIR}")
add_dependencies(contact_convergence_bench neurosim-model)
