# interaction_bench: contact step with the exact tie, full-field displacement and the
# iterative baseline on the cube/cylinder and a brain-sized scene. `interaction_bench --csv`.
add_executable(interaction_bench ${CMAKE_CURRENT_LIST_DIR}/interaction_bench.cpp)
target_link_libraries(interaction_bench PRIVATE neurosim::interaction neurosim::scene neurosim::fem neurosim::common neurosim_warnings)
target_compile_definitions(interaction_bench PRIVATE NEUROSIM_SOURCE_DIR="${NEUROSIM_SOURCE_DIR}")
