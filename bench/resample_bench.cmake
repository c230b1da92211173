# resample_bench: the MRI resampled through the deformed brain/artery model (three
# slices through the tool tip, the whole volume; full and incremental). `resample_bench --csv`.
# The NIfTI MRI is read as the viewer reads it (viewer::load_nifti over neurosim::nifti); the
# library neurosim::resample stays Eigen-only.
add_executable(resample_bench ${CMAKE_CURRENT_LIST_DIR}/resample_bench.cpp)
target_link_libraries(resample_bench PRIVATE neurosim::viewer neurosim::resample neurosim::scene
                                             neurosim::common neurosim_warnings)
target_include_directories(resample_bench PRIVATE ${NEUROSIM_SOURCE_DIR})
target_compile_definitions(resample_bench PRIVATE NEUROSIM_SOURCE_DIR="${NEUROSIM_SOURCE_DIR}")
