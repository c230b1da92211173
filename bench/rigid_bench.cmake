# rigid_bench: the step cost added by the rigid obstacles (the skull of scenes/brain_skull.scene):
# the tool proxy's query + projection per step along approach paths (far, into the skull, through
# the opening), side by side with the contact step. `--csv` for CSV.
add_executable(rigid_bench ${CMAKE_CURRENT_LIST_DIR}/rigid_bench.cpp)
target_link_libraries(rigid_bench PRIVATE neurosim::interaction neurosim::scene neurosim::common neurosim_warnings)
target_include_directories(rigid_bench PRIVATE ${NEUROSIM_SOURCE_DIR})
target_compile_definitions(rigid_bench PRIVATE NEUROSIM_SOURCE_DIR="${NEUROSIM_SOURCE_DIR}")
