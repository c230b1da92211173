# resample_bench: the MRI resampled through the deformed brain/artery model (three
# slices through the tool tip, the whole volume; full and incremental). `resample_bench --csv`.
# VTK reads the NIfTI MRI here only; the library neurosim::resample stays Eigen-only.
if(TARGET neurosim::resample AND TARGET neurosim::scene)
  find_package(VTK COMPONENTS IOImage ImagingCore CommonCore CommonDataModel QUIET)
  if(NOT VTK_FOUND)
    message(STATUS "resample_bench: VTK not found (apt-get install libvtk9-dev), bench skipped")
  else()
    add_executable(resample_bench ${CMAKE_CURRENT_LIST_DIR}/resample_bench.cpp)
    target_link_libraries(resample_bench PRIVATE neurosim::resample neurosim::scene
                                                 ${VTK_LIBRARIES} neurosim_warnings)
    target_include_directories(resample_bench PRIVATE ${NEUROSIM_SOURCE_DIR})
    target_compile_definitions(resample_bench PRIVATE NEUROSIM_SOURCE_DIR="${NEUROSIM_SOURCE_DIR}")
    vtk_module_autoinit(TARGETS resample_bench MODULES ${VTK_LIBRARIES})
  endif()
endif()
