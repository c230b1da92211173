# accuracy_bench: what accuracy costs in time (tiers x resolutions x coupling over recorded
# presses, errors against the finest nonlinear run and CalculiX). `accuracy_bench --csv --out DIR`.
add_executable(accuracy_bench ${CMAKE_CURRENT_LIST_DIR}/accuracy_bench.cpp)
target_link_libraries(accuracy_bench PRIVATE neurosim::replay neurosim::interaction neurosim::scene
                                             neurosim::service
                                             neurosim::fem neurosim::common neurosim_warnings)
target_compile_definitions(accuracy_bench PRIVATE NEUROSIM_SOURCE_DIR="${NEUROSIM_SOURCE_DIR}"
                                                  NEUROSIM_BIN_DIR="${CMAKE_RUNTIME_OUTPUT_DIRECTORY}")
