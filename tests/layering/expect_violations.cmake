# ctest `layering_detects_violation`: cmake/check_layering.cmake run on fixtures/bad must fail and
# name each planted violation (file:line and include chain, followed transitively; target chain),
# and nothing else.
#   cmake -DCHECK_SCRIPT=<check_layering.cmake> -DFIXTURE_DIR=<fixtures/bad> -P expect_violations.cmake
execute_process(
  COMMAND ${CMAKE_COMMAND} -DSOURCE_DIR=${FIXTURE_DIR} -DLINK_GRAPH=${FIXTURE_DIR}/link_graph.cmake
          -P ${CHECK_SCRIPT}
  RESULT_VARIABLE _rc OUTPUT_VARIABLE _out ERROR_VARIABLE _err)
set(_all "${_out}${_err}")
message("${_all}")
set(_failed FALSE)
if(_rc EQUAL 0)
  message(STATUS "expect_violations: the check passed on the bad fixture")
  set(_failed TRUE)
endif()
set(_expected
  "server/fem/bad_proto.cpp:3: includes scene.pb.h"
  "server/fusion/bad_dds.hpp:3: includes dds/dds.h"
  "server/interaction/bad_scene.cpp:2: includes server/scene/scene.hpp"
  "server/interaction/bad_scene.cpp:3: includes idl/wire/dds.hpp"
  "server/interaction/bad_scene.cpp:4: includes neurosim.h"
  "neurosim_fem links neurosim_proto (the physics core links no protobuf and no DDS): neurosim_fem -> neurosim_helper -> neurosim_proto"
  "neurosim_interaction links neurosim_wire (the physics core links no protobuf and no DDS): neurosim_interaction -> neurosim_wire"
  "neurosim_interaction links neurosim_proto (the physics core links no protobuf and no DDS): neurosim_interaction -> neurosim_wire -> neurosim_proto"
  "neurosim-haptic links neurosim_interaction (the clients get physics over DDS only): neurosim-haptic -> neurosim_interaction"
  "neurosim_viewer_core links neurosim_fem (the clients get physics over DDS only): neurosim_viewer_core -> neurosim_fem"
  "neurosim_viewer links neurosim_fem (the clients get physics over DDS only): neurosim_viewer -> neurosim_viewer_core -> neurosim_fem"
  "web/bad_bridge.cpp:2: includes server/fem/material.hpp"
  "web/bad_bridge.cpp:5: creates a DDS writer"
  "neurosim_web links neurosim_mesh (the web observer links idl/ and common/ only): neurosim_web -> neurosim_mesh"
  "neurosim-web links neurosim_mesh (the web observer links idl/ and common/ only): neurosim-web -> neurosim_web -> neurosim_mesh"
  "server/interaction/bad_chain.cpp:2: includes server/scene/compile.hpp -> scene.pb.h"
  "haptic_client/bad_client.cpp:2: includes haptic_client/bad_local.hpp -> server/fem/assembly.hpp (the clients"
  "haptic_client/bad_local.hpp:2: includes server/fem/assembly.hpp (the clients"
  "web/bad_page.cpp:2: includes web/helper.hpp -> server/mesh/tet_mesh.hpp (the web"
  "web/helper.hpp:2: includes server/mesh/tet_mesh.hpp (the web"
  "layering: 20 violation(s)")
foreach(_e IN LISTS _expected)
  string(FIND "${_all}" "${_e}" _pos)
  if(_pos EQUAL -1)
    message(STATUS "expect_violations: missing from the report: ${_e}")
    set(_failed TRUE)
  endif()
endforeach()
foreach(_clean "clean.hpp" "server/scene/compile.hpp:" "server/fem/assembly.cpp:" "tier.hpp (the clients" "neurosim_mesh links" "neurosim_fusion links" "neurosim_haptic links"
               "neurosim_resample links" "includes idl/wire/dds.hpp (the web"
               "includes common/json.hpp" "links neurosim_wire (the web" "links neurosim_common"
               "links neurosim_proto (the web")
  string(FIND "${_all}" "${_clean}" _pos)
  if(NOT _pos EQUAL -1)
    message(STATUS "expect_violations: reported although clean: ${_clean}")
    set(_failed TRUE)
  endif()
endforeach()
if(_failed)
  message(FATAL_ERROR "expect_violations: the layering check does not detect the planted violations")
endif()
message(STATUS "expect_violations: every planted violation reported")
