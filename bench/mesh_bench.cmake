# mesh_bench: TetMesh::build, Medit read and .vtu write on a ~25k-tetrahedron mesh.
add_executable(mesh_bench ${CMAKE_CURRENT_LIST_DIR}/mesh_bench.cpp)
target_link_libraries(mesh_bench PRIVATE neurosim::mesh benchmark::benchmark neurosim_warnings)
target_include_directories(mesh_bench PRIVATE ${NEUROSIM_SOURCE_DIR})
