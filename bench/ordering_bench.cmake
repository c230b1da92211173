# ordering_bench: the brain/artery scene's host factor per fill-reducing ordering (nnz(L), memory,
# analysis and factorization time, solves, the answer against the first ordering), per brain cell
# size. `ordering_bench --cell-size 5 --cell-size 3 --csv`.
add_executable(ordering_bench ${CMAKE_CURRENT_LIST_DIR}/ordering_bench.cpp)
target_link_libraries(ordering_bench PRIVATE neurosim::fem neurosim::scene neurosim::common neurosim_warnings)
target_compile_definitions(ordering_bench PRIVATE NEUROSIM_BIN_DIR="${CMAKE_RUNTIME_OUTPUT_DIRECTORY}")
add_dependencies(ordering_bench neurosim-model)
