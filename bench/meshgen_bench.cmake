# meshgen_bench: generated cube/cylinder vertex and tetrahedron counts against the paper's.
add_executable(meshgen_bench ${CMAKE_CURRENT_LIST_DIR}/meshgen_bench.cpp)
target_link_libraries(meshgen_bench PRIVATE neurosim::meshgen neurosim::mesh neurosim::common neurosim_warnings)
target_include_directories(meshgen_bench PRIVATE ${NEUROSIM_SOURCE_DIR})
target_compile_definitions(meshgen_bench PRIVATE NEUROSIM_SOURCE_DIR="${NEUROSIM_SOURCE_DIR}")
