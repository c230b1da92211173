# scale_bench: the brain/artery scene at several cell sizes (built by neurosim-model when missing):
# set-up cold and from the disk cache, memory, the contact step along a slide over fresh surface,
# the full-field rate. `scale_bench --cell-size 7 --cell-size 5 ... --csv`.
add_executable(scale_bench ${CMAKE_CURRENT_LIST_DIR}/scale_bench.cpp)
target_link_libraries(scale_bench PRIVATE neurosim::interaction neurosim::scene neurosim::common neurosim_warnings)
target_compile_definitions(scale_bench PRIVATE NEUROSIM_BIN_DIR="${CMAKE_RUNTIME_OUTPUT_DIRECTORY}")
add_dependencies(scale_bench neurosim-model)
