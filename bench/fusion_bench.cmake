# fusion_bench: the paper's Table 3 side by side with brute force and the fast
# inclusion decision, plus a brain-sized pair. `fusion_bench --csv` prints the table.
add_executable(fusion_bench ${CMAKE_CURRENT_LIST_DIR}/fusion_bench.cpp)
target_link_libraries(fusion_bench PRIVATE neurosim::fusion_models neurosim::common neurosim_warnings)
target_compile_definitions(fusion_bench PRIVATE NEUROSIM_SOURCE_DIR="${NEUROSIM_SOURCE_DIR}")
