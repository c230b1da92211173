# haptic_bench: N seconds (default 60) of the 1 kHz haptic loop talking DDS to a server
# (neurosim-server process with --server, else the test-only in-process fake), at normal
# priority and with SCHED_FIFO where permitted.
add_executable(haptic_bench ${CMAKE_CURRENT_LIST_DIR}/haptic_bench.cpp)
target_link_libraries(haptic_bench PRIVATE neurosim::haptic neurosim::common neurosim_warnings)
target_include_directories(haptic_bench PRIVATE ${NEUROSIM_SOURCE_DIR} ${NEUROSIM_SOURCE_DIR}/tests/haptic_client)
