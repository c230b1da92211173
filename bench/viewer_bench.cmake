# viewer_bench: neurosim-viewer's frame rate (surfaces + slices, volume rendering) and
# slice resample time per frame on the brain/artery scene, offscreen under Xvfb, no DDS.
#   xvfb-run -a build/bin/viewer_bench [--frames N] [--size WxH] [--csv]
add_executable(viewer_bench ${CMAKE_CURRENT_LIST_DIR}/viewer_bench.cpp)
target_link_libraries(viewer_bench PRIVATE neurosim::viewer neurosim::scene neurosim::common neurosim_warnings)
target_compile_definitions(viewer_bench PRIVATE NEUROSIM_SOURCE_DIR="${NEUROSIM_SOURCE_DIR}")
