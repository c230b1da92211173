# fem_bench: assembly, CHOLMOD factorization, compliance columns (single vs block),
# factor memory for a series of cube meshes up to ~25k tetrahedra. `fem_bench --csv` for CSV.
# Structured grid cubes, and the paper's Table 3 cube series from the CGAL generator (meshgen).
add_executable(fem_bench ${CMAKE_CURRENT_LIST_DIR}/fem_bench.cpp)
target_link_libraries(fem_bench PRIVATE neurosim::fem neurosim::meshgen neurosim::common neurosim_warnings)
target_include_directories(fem_bench PRIVATE ${NEUROSIM_SOURCE_DIR})
