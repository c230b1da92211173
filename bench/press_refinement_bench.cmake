# press_refinement_bench: the coarse brain's patch press (FemBrainPress's) in CalculiX C3D10
# (NLGEOM and linear), smoothed-tet and linear-tet (NONLINEAR and LINEAR), on the mesh and its
# 1 -> 8 splits (tet_split.hpp), optionally on the press's sub-model (sub_model.hpp, --region):
# C3D10's own error on the coarse mesh against the elements' ratio to it.
# `press_refinement_bench --out DIR --region 40 --splits 1 --depth 10 --nu 0.49`.
add_executable(press_refinement_bench ${CMAKE_CURRENT_LIST_DIR}/press_refinement_bench.cpp)
target_link_libraries(press_refinement_bench PRIVATE neurosim::scene neurosim::fem neurosim::common
                      neurosim_warnings)
target_compile_definitions(press_refinement_bench PRIVATE NEUROSIM_BIN_DIR="${CMAKE_RUNTIME_OUTPUT_DIRECTORY}")
add_dependencies(press_refinement_bench neurosim-model)
