# latency_bench: ToolState written → the ContactModel answering it read, over loopback
# DDS, with a real neurosim-server child process and N scripted stations.
#   latency_bench --stations N --seconds S --csv
add_executable(latency_bench ${CMAKE_CURRENT_LIST_DIR}/latency_bench.cpp)
target_link_libraries(latency_bench PRIVATE neurosim::wire Threads::Threads neurosim::common neurosim_warnings)
target_compile_definitions(latency_bench PRIVATE NEUROSIM_SOURCE_DIR="${NEUROSIM_SOURCE_DIR}"
                                                 NEUROSIM_LOOPBACK_URI="${NEUROSIM_LOOPBACK_URI}")
add_dependencies(latency_bench neurosim-server)
