# Layering check (ctest `layering`):
#   cmake -DSOURCE_DIR=<source tree> -DLINK_GRAPH=<build>/layering/link_graph.cmake \
#         -P cmake/check_layering.cmake
# LINK_GRAPH is written at configure time by neurosim_write_link_graph
# (cmake/NeurosimLinkGraph.cmake). Fails (exit code 1) and names every violation:
#   1. a source or header under server/mesh, server/fem, server/fusion, server/model or server/interaction that
#      includes a generated protobuf header (*.pb.h), a DDS header (dds/..., idl/wire/..., the
#      idlc-generated neurosim.h) or the scene file reader server/scene/scene.hpp;
#   2. neurosim_mesh, neurosim_fem, neurosim_fusion or neurosim_interaction linking, directly or
#      through any target in between, neurosim_proto or neurosim_wire;
#   3. a haptic_client target (neurosim_haptic, neurosim-haptic) or any target defined under
#      viewer_client/ linking, directly or not, neurosim_fem or neurosim_interaction;
#   4. the web observer (web/) stepping outside the contracts: a source under web/ that includes a
#      header of server/, haptic_client/, viewer_client/, tools/, bench/ or tests/, or that creates
#      a DDS writer (`Writer<`, `dds_create_writer`: the bridge is read-only by construction), or
#      a target defined under web/ linking, directly or not, any target of this project outside
#      idl/, common/ and web/.
# tests/layering/fixtures/ holds a tree and a graph with one violation of each kind
# (ctest `layering_detects_violation`).
cmake_minimum_required(VERSION 3.22)

if(NOT SOURCE_DIR OR NOT LINK_GRAPH)
  message(FATAL_ERROR "usage: cmake -DSOURCE_DIR=<dir> -DLINK_GRAPH=<file> -P check_layering.cmake")
endif()
if(NOT IS_DIRECTORY "${SOURCE_DIR}")
  message(FATAL_ERROR "layering: SOURCE_DIR ${SOURCE_DIR} is not a directory")
endif()
if(NOT EXISTS "${LINK_GRAPH}")
  message(FATAL_ERROR "layering: link graph ${LINK_GRAPH} missing (written when CMake configures)")
endif()

set(_violations 0)

# --- 1. Includes of the physics core -------------------------------------------------------------
set(_core_dirs server/mesh server/fem server/fusion server/model server/interaction)
set(_bad_include_regex "(\\.pb\\.h$|^dds/|/dds/|^idl/wire/|/idl/wire/|(^|/)neurosim\\.h$|(^|/)scene/scene\\.hpp$)")
set(_checked_files 0)
foreach(_dir IN LISTS _core_dirs)
  if(NOT IS_DIRECTORY "${SOURCE_DIR}/${_dir}")
    message(FATAL_ERROR "layering: ${SOURCE_DIR}/${_dir} missing")
  endif()
  file(GLOB_RECURSE _files LIST_DIRECTORIES false
       "${SOURCE_DIR}/${_dir}/*.h" "${SOURCE_DIR}/${_dir}/*.hpp" "${SOURCE_DIR}/${_dir}/*.hh"
       "${SOURCE_DIR}/${_dir}/*.inl" "${SOURCE_DIR}/${_dir}/*.ipp" "${SOURCE_DIR}/${_dir}/*.c"
       "${SOURCE_DIR}/${_dir}/*.cc" "${SOURCE_DIR}/${_dir}/*.cpp" "${SOURCE_DIR}/${_dir}/*.cxx")
  list(SORT _files)
  foreach(_file IN LISTS _files)
    math(EXPR _checked_files "${_checked_files} + 1")
    file(RELATIVE_PATH _rel "${SOURCE_DIR}" "${_file}")
    file(STRINGS "${_file}" _lines)
    set(_n 0)
    foreach(_line IN LISTS _lines)
      math(EXPR _n "${_n} + 1")
      if(_line MATCHES "^[ \t]*#[ \t]*include[ \t]*[<\"]([^>\"]+)[>\"]")
        set(_header "${CMAKE_MATCH_1}")
        if(_header MATCHES "${_bad_include_regex}")
          message(STATUS "layering: ${_rel}:${_n}: includes ${_header} "
                         "(the physics core must not see protobuf, DDS or the scene file reader)")
          math(EXPR _violations "${_violations} + 1")
        endif()
      endif()
    endforeach()
  endforeach()
endforeach()
if(_checked_files EQUAL 0)
  message(FATAL_ERROR "layering: no sources found under ${_core_dirs} in ${SOURCE_DIR}")
endif()

# --- 2./3. Link closures -------------------------------------------------------------------------
include("${LINK_GRAPH}")

# A shortest chain of direct links from <from> to <to>, as "a -> b -> c".
function(_layering_chain from to out)
  set(_seen "${from}")
  set(_queue "${from}")
  set("_parent[${from}]" "")
  while(_queue)
    list(POP_FRONT _queue _t)
    if(_t STREQUAL to)
      break()
    endif()
    foreach(_l IN LISTS "NEUROSIM_LAYERING_LINKS[${_t}]")
      if(NOT _l IN_LIST _seen)
        list(APPEND _seen "${_l}")
        set("_parent[${_l}]" "${_t}")
        list(APPEND _queue "${_l}")
      endif()
    endforeach()
  endwhile()
  set(_chain "${to}")
  set(_t "${to}")
  while(NOT _t STREQUAL from)
    set(_key "_parent[${_t}]")
    set(_t "${${_key}}")
    if(_t STREQUAL "")
      set(_chain "${from} -> ... -> ${to} (not found in the direct links)")
      break()
    endif()
    set(_chain "${_t} -> ${_chain}")
  endwhile()
  set(${out} "${_chain}" PARENT_SCOPE)
endfunction()

# Fails when <target> has any of <forbidden> in its closure; <why> explains the rule.
function(_layering_forbid target forbidden why)
  if(NOT DEFINED "NEUROSIM_LAYERING_CLOSURE[${target}]")
    message(STATUS "layering: target ${target} is not in the link graph")
    set(_violations_add 1 PARENT_SCOPE)
    return()
  endif()
  set(_n 0)
  foreach(_f IN LISTS forbidden)
    if(_f IN_LIST "NEUROSIM_LAYERING_CLOSURE[${target}]")
      _layering_chain("${target}" "${_f}" _chain)
      message(STATUS "layering: ${target} links ${_f} (${why}): ${_chain}")
      math(EXPR _n "${_n} + 1")
    endif()
  endforeach()
  set(_violations_add ${_n} PARENT_SCOPE)
endfunction()

# The aliases are resolved in the graph; the alias names are listed too in case a graph has them.
set(_wire_proto neurosim_proto neurosim_wire neurosim::proto neurosim::wire)
set(_physics neurosim_fem neurosim_interaction neurosim::fem neurosim::interaction)

foreach(_t neurosim_mesh neurosim_fem neurosim_fusion neurosim_interaction)
  _layering_forbid(${_t} "${_wire_proto}" "the physics core links no protobuf and no DDS")
  math(EXPR _violations "${_violations} + ${_violations_add}")
endforeach()

set(_clients neurosim_haptic neurosim-haptic)
set(_viewer_targets "")
foreach(_t IN LISTS NEUROSIM_LAYERING_TARGETS)
  set(_key "NEUROSIM_LAYERING_DIR[${_t}]")
  set(_dir "${${_key}}")
  if(_dir STREQUAL "viewer_client" OR _dir MATCHES "^viewer_client/")
    list(APPEND _viewer_targets ${_t})
  endif()
endforeach()
if(NOT _viewer_targets)
  message(STATUS "layering: no target defined under viewer_client/ in the link graph")
  math(EXPR _violations "${_violations} + 1")
endif()
list(APPEND _clients ${_viewer_targets})
foreach(_t IN LISTS _clients)
  _layering_forbid(${_t} "${_physics}" "the clients get physics over DDS only")
  math(EXPR _violations "${_violations} + ${_violations_add}")
endforeach()

# --- 4. The web observer: the contracts (idl/) and common/ only, no DDS writer ---------------------
if(NOT IS_DIRECTORY "${SOURCE_DIR}/web")
  message(FATAL_ERROR "layering: ${SOURCE_DIR}/web missing")
endif()
set(_web_bad_include_regex "^(server|haptic_client|viewer_client|tools|bench|tests)/")
file(GLOB_RECURSE _web_files LIST_DIRECTORIES false
     "${SOURCE_DIR}/web/*.h" "${SOURCE_DIR}/web/*.hpp" "${SOURCE_DIR}/web/*.cpp")
list(FILTER _web_files EXCLUDE REGEX "/node_modules/")
list(SORT _web_files)
foreach(_file IN LISTS _web_files)
  file(RELATIVE_PATH _rel "${SOURCE_DIR}" "${_file}")
  file(STRINGS "${_file}" _lines)
  set(_n 0)
  foreach(_line IN LISTS _lines)
    math(EXPR _n "${_n} + 1")
    if(_line MATCHES "^[ \t]*#[ \t]*include[ \t]*[<\"]([^>\"]+)[>\"]")
      set(_header "${CMAKE_MATCH_1}")
      if(_header MATCHES "${_web_bad_include_regex}")
        message(STATUS "layering: ${_rel}:${_n}: includes ${_header} "
                       "(the web observer knows the contracts in idl/ and common/ only)")
        math(EXPR _violations "${_violations} + 1")
      endif()
    elseif(_line MATCHES "Writer<|dds_create_writer")
      message(STATUS "layering: ${_rel}:${_n}: creates a DDS writer (the web observer is read-only)")
      math(EXPR _violations "${_violations} + 1")
    endif()
  endforeach()
endforeach()

set(_web_targets "")
foreach(_t IN LISTS NEUROSIM_LAYERING_TARGETS)
  set(_key "NEUROSIM_LAYERING_DIR[${_t}]")
  if("${${_key}}" MATCHES "^web(/|$)")
    list(APPEND _web_targets ${_t})
  endif()
endforeach()
if(NOT _web_targets)
  message(STATUS "layering: no target defined under web/ in the link graph")
  math(EXPR _violations "${_violations} + 1")
endif()
foreach(_t IN LISTS _web_targets)
  foreach(_l IN LISTS "NEUROSIM_LAYERING_CLOSURE[${_t}]")
    if(NOT _l IN_LIST NEUROSIM_LAYERING_TARGETS)
      continue()  # third-party (imported) libraries
    endif()
    set(_key "NEUROSIM_LAYERING_DIR[${_l}]")
    set(_dir "${${_key}}")
    if(NOT _dir STREQUAL "" AND NOT _dir MATCHES "^(idl|common|web)(/|$)")
      _layering_chain("${_t}" "${_l}" _chain)
      message(STATUS "layering: ${_t} links ${_l} (the web observer links idl/ and common/ only): "
                     "${_chain}")
      math(EXPR _violations "${_violations} + 1")
    endif()
  endforeach()
endforeach()

list(LENGTH _clients _n_clients)
list(LENGTH _web_targets _n_web)
if(_violations GREATER 0)
  message(FATAL_ERROR "layering: ${_violations} violation(s)")
endif()
message(STATUS "layering: OK (${_checked_files} physics-core files; 4 core and ${_n_clients} client "
               "targets: ${_clients}; ${_n_web} web targets: ${_web_targets})")
