# web_bench: the web observer on loopback: bytes per deformation frame of the brain/artery scene
# (FULL vs delta), frames/s delivered to 1 and 10 WebSocket clients, Deformation-to-WebSocket
# latency p50/p99, with neurosim-web as a child process.
#   web_bench [--seconds S] [--csv]
add_executable(web_bench ${CMAKE_CURRENT_LIST_DIR}/web_bench.cpp)
target_link_libraries(web_bench PRIVATE neurosim::web neurosim::mesh CivetWeb::civetweb
                                        neurosim::common neurosim_warnings)
target_compile_definitions(web_bench PRIVATE NEUROSIM_SOURCE_DIR="${NEUROSIM_SOURCE_DIR}")
add_dependencies(web_bench neurosim-web)
