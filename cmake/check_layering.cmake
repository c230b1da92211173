# Layering check (ctest `layering`):
#   cmake -DSOURCE_DIR=<source tree> -DLINK_GRAPH=<build>/layering/link_graph.cmake \
#         -P cmake/check_layering.cmake
# LINK_GRAPH is written at configure time by neurosim_write_link_graph
# (cmake/NeurosimLinkGraph.cmake). Fails (exit code 1) and names every violation:
#   1. a source or header under server/mesh, server/fem, server/fusion, server/model or
#      server/interaction that includes, directly or through headers of this tree (includes are
#      followed transitively, the chain is named), a generated protobuf header (*.pb.h), a DDS
#      header (dds/..., idl/wire/..., the idlc-generated neurosim.h) or the scene file reader
#      server/scene/scene.hpp;
#   2. neurosim_mesh, neurosim_fem, neurosim_fusion or neurosim_interaction linking, directly or
#      through any target in between, neurosim_proto or neurosim_wire;
#   3. a haptic_client target (neurosim_haptic, neurosim-haptic) or any target defined under
#      viewer_client/ linking, directly or not, neurosim_fem or neurosim_interaction, or a source
#      under haptic_client/ or viewer_client/ including, directly or not, a header of server/fem
#      or server/interaction with a compiled counterpart (header-only vocabulary such as
#      server/fem/tier.hpp is allowed);
#   4. the web observer (web/) stepping outside the contracts: a source under web/ that includes,
#      directly or not, a header of server/, haptic_client/, viewer_client/, tools/, bench/ or
#      tests/, or that creates
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

# --- Includes, followed transitively ----------------------------------------------------------
# An include is followed when it names a file of this tree (relative to SOURCE_DIR, else to the
# including file's folder); every header named on the way is matched against the rule, so a chain
# through an allowed header (interaction -> server/scene/compile.hpp -> scene.pb.h) is caught.
# The first offending chain of each include line is reported as "a -> b -> bad".

# The includes of one file as a list of "line|header" (memoized).
function(_layering_includes file out)
  get_property(_have GLOBAL PROPERTY "_layering_inc[${file}]" SET)
  if(_have)
    get_property(_inc GLOBAL PROPERTY "_layering_inc[${file}]")
    set(${out} "${_inc}" PARENT_SCOPE)
    return()
  endif()
  set(_inc "")
  file(STRINGS "${file}" _lines)
  set(_n 0)
  foreach(_line IN LISTS _lines)
    math(EXPR _n "${_n} + 1")
    if(_line MATCHES "^[ \t]*#[ \t]*include[ \t]*[<\"]([^>\"]+)[>\"]")
      list(APPEND _inc "${_n}|${CMAKE_MATCH_1}")
    endif()
  endforeach()
  set_property(GLOBAL PROPERTY "_layering_inc[${file}]" "${_inc}")
  set(${out} "${_inc}" PARENT_SCOPE)
endfunction()

# The file an include names in this tree, or "".
function(_layering_resolve header from_file out)
  get_filename_component(_dir "${from_file}" DIRECTORY)
  if(EXISTS "${SOURCE_DIR}/${header}" AND NOT IS_DIRECTORY "${SOURCE_DIR}/${header}")
    set(${out} "${SOURCE_DIR}/${header}" PARENT_SCOPE)
  elseif(EXISTS "${_dir}/${header}" AND NOT IS_DIRECTORY "${_dir}/${header}")
    get_filename_component(_abs "${_dir}/${header}" ABSOLUTE)
    set(${out} "${_abs}" PARENT_SCOPE)
  else()
    set(${out} "" PARENT_SCOPE)
  endif()
endfunction()

# The first chain "h1 -> h2 -> bad" from the includes of <file> (not <file> itself) to a header
# matching <regex>, or "" (memoized per file and rule).
function(_layering_bad_chain file rule regex out)
  set(_key "_layering_chain[${rule}][${file}]")
  get_property(_have GLOBAL PROPERTY "${_key}" SET)
  if(_have)
    get_property(_c GLOBAL PROPERTY "${_key}")
    set(${out} "${_c}" PARENT_SCOPE)
    return()
  endif()
  set_property(GLOBAL PROPERTY "${_key}" "")  # in progress: a cycle ends here
  _layering_includes("${file}" _inc)
  set(_found "")
  foreach(_e IN LISTS _inc)
    string(REGEX REPLACE "^[0-9]+\\|" "" _h "${_e}")
    if(_h MATCHES "${regex}")
      set(_found "${_h}")
      break()
    endif()
    _layering_resolve("${_h}" "${file}" _next)
    if(_next)
      _layering_bad_chain("${_next}" "${rule}" "${regex}" _sub)
      if(_sub)
        set(_found "${_h} -> ${_sub}")
        break()
      endif()
    endif()
  endforeach()
  set_property(GLOBAL PROPERTY "${_key}" "${_found}")
  set(${out} "${_found}" PARENT_SCOPE)
endfunction()

# Reports every include line of the files under <dirs> that reaches a header matching <regex>,
# directly or through headers of this tree. Adds the count to _violations and the number of
# files to _checked_files.
macro(_layering_check_includes rule dirs regex why)
  foreach(_dir IN ITEMS ${dirs})
    if(NOT IS_DIRECTORY "${SOURCE_DIR}/${_dir}")
      message(FATAL_ERROR "layering: ${SOURCE_DIR}/${_dir} missing")
    endif()
    file(GLOB_RECURSE _files LIST_DIRECTORIES false
         "${SOURCE_DIR}/${_dir}/*.h" "${SOURCE_DIR}/${_dir}/*.hpp" "${SOURCE_DIR}/${_dir}/*.hh"
         "${SOURCE_DIR}/${_dir}/*.inl" "${SOURCE_DIR}/${_dir}/*.ipp" "${SOURCE_DIR}/${_dir}/*.c"
         "${SOURCE_DIR}/${_dir}/*.cc" "${SOURCE_DIR}/${_dir}/*.cpp" "${SOURCE_DIR}/${_dir}/*.cxx")
    list(FILTER _files EXCLUDE REGEX "/node_modules/")
    list(SORT _files)
    foreach(_file IN LISTS _files)
      math(EXPR _checked_files "${_checked_files} + 1")
      file(RELATIVE_PATH _rel "${SOURCE_DIR}" "${_file}")
      _layering_includes("${_file}" _inc)
      foreach(_e IN LISTS _inc)
        string(REGEX MATCH "^[0-9]+" _n "${_e}")
        string(REGEX REPLACE "^[0-9]+\\|" "" _h "${_e}")
        set(_chain "")
        if(_h MATCHES "${regex}")
          set(_chain "${_h}")
        else()
          _layering_resolve("${_h}" "${_file}" _next)
          if(_next)
            _layering_bad_chain("${_next}" "${rule}" "${regex}" _sub)
            if(_sub)
              set(_chain "${_h} -> ${_sub}")
            endif()
          endif()
        endif()
        if(_chain)
          message(STATUS "layering: ${_rel}:${_n}: includes ${_chain} (${why})")
          math(EXPR _violations "${_violations} + 1")
        endif()
      endforeach()
    endforeach()
  endforeach()
endmacro()

# --- 1. Includes of the physics core -------------------------------------------------------------
set(_core_dirs server/mesh server/fem server/fusion server/model server/interaction)
set(_bad_include_regex "(\\.pb\\.h$|^dds/|/dds/|^idl/wire/|/idl/wire/|(^|/)neurosim\\.h$|(^|/)scene/scene\\.hpp$)")
set(_checked_files 0)
_layering_check_includes(core "${_core_dirs}" "${_bad_include_regex}"
  "the physics core must not see protobuf, DDS or the scene file reader")
if(_checked_files EQUAL 0)
  message(FATAL_ERROR "layering: no sources found under ${_core_dirs} in ${SOURCE_DIR}")
endif()
set(_core_files ${_checked_files})

# --- 3a. Includes of the clients: no physics header, directly or not -----------------------------
set(_client_dirs "")
foreach(_d haptic_client viewer_client)
  if(IS_DIRECTORY "${SOURCE_DIR}/${_d}")
    list(APPEND _client_dirs ${_d})
  endif()
endforeach()
# A physics header is one with a compiled counterpart (server/fem/assembly.hpp: assembly.cpp in
# neurosim::fem, which the clients do not link); header-only vocabulary (server/fem/tier.hpp, the
# Tier enum the scene settings name) is allowed.
set(_physics_headers "")
foreach(_d server/fem server/interaction)
  file(GLOB _cpps LIST_DIRECTORIES false "${SOURCE_DIR}/${_d}/*.cpp")
  foreach(_c IN LISTS _cpps)
    get_filename_component(_stem "${_c}" NAME_WE)
    list(APPEND _physics_headers "${_d}/${_stem}")
  endforeach()
endforeach()
if(_physics_headers)
  list(JOIN _physics_headers "|" _alt)
  string(REPLACE "." "\\." _alt "${_alt}")
  _layering_check_includes(client "${_client_dirs}" "^(${_alt})\\.hpp$"
    "the clients get physics over DDS only")
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
_layering_check_includes(web "web" "${_web_bad_include_regex}"
  "the web observer knows the contracts in idl/ and common/ only")
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
    if(NOT _line MATCHES "^[ \t]*#[ \t]*include" AND _line MATCHES "Writer<|dds_create_writer")
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
message(STATUS "layering: OK (${_core_files} physics-core files, ${_checked_files} with the clients and web; 4 core and ${_n_clients} client "
               "targets: ${_clients}; ${_n_web} web targets: ${_web_targets})")
