# What cmake/check_layering.cmake must report on fixtures/bad (tests/expect_violations.cmake):
# each planted violation (file:line and include chain, followed transitively; target chain), and
# nothing else.
set(WHAT "layering check")
set(EXPECTED
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
set(CLEAN "clean.hpp" "server/scene/compile.hpp:" "server/fem/assembly.cpp:" "tier.hpp (the clients"
          "neurosim_mesh links" "neurosim_fusion links" "neurosim_haptic links"
          "neurosim_resample links" "includes idl/wire/dds.hpp (the web"
          "includes common/json.hpp" "links neurosim_wire (the web" "links neurosim_common"
          "links neurosim_proto (the web")
