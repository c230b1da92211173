// Viewer state and command line: topology/deformation ingestion, malformed samples
// counted and ignored, the paper's tool colour rule, option errors.
#include "viewer_client/viewer/state.hpp"
#include "idl/wire/deformation_codec.hpp"
#include "viewer_client/viewer/options.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace nv = neurosim::viewer;
namespace wire = neurosim::wire;

namespace {

// One tetrahedron, its four faces as surface.
void fill_topology(neurosim_MeshTopology& t, const char* id) {
  wire::set_string(t.mesh_id, id);
  t.revision = 1;
  const double v[] = {0, 0, 0, 0.01, 0, 0, 0, 0.01, 0, 0, 0, 0.01};
  wire::assign(t.rest_vertices_m, v, 12);
  const std::int32_t tet[] = {0, 1, 2, 3};
  wire::assign(t.tetrahedra, tet, 4);
  const std::int32_t tri[] = {0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3};
  wire::assign(t.surface_triangles, tri, 12);
  wire::set_string(t.volume_image_file, "/nonexistent.nii.gz");
  t.volume_image_unit_m = 0.001;
}

}  // namespace

TEST(ViewerState, ForceColourIsThePapersRule) {
  const auto c0 = nv::force_colour(0.0);
  EXPECT_DOUBLE_EQ(c0[0], 0.2);
  EXPECT_DOUBLE_EQ(c0[1], 0.2);
  EXPECT_DOUBLE_EQ(c0[2], 0.2);
  const auto c1 = nv::force_colour(0.1);
  EXPECT_NEAR(c1[0], 0.3, 1e-15);
  EXPECT_NEAR(c1[1], 0.1, 1e-15);
  const auto c2 = nv::force_colour(2.0);
  EXPECT_DOUBLE_EQ(c2[0], 1.0);
  EXPECT_DOUBLE_EQ(c2[1], 0.0);
  // --force-unit 0.5: f = |F| / 0.5 N.
  EXPECT_NEAR(nv::force_colour(0.1, 0.5)[0], 0.4, 1e-15);
  EXPECT_DOUBLE_EQ(nv::force_colour(std::numeric_limits<double>::quiet_NaN())[0], 1.0);
}

TEST(ViewerState, ShaftAxisIsToolZ) {
  EXPECT_TRUE(nv::shaft_axis(1, 0, 0, 0).isApprox(Eigen::Vector3d::UnitZ()));
  // 90 degrees about y: z -> x.
  const double h = std::sqrt(0.5);
  EXPECT_TRUE(nv::shaft_axis(h, 0, h, 0).isApprox(Eigen::Vector3d::UnitX(), 1e-12));
}

TEST(ViewerState, TopologyAndDeformationFrames) {
  std::vector<std::string> warnings;
  nv::ViewerState s([&](const std::string& m) { warnings.push_back(m); });
  wire::Sample<neurosim_MeshTopology> t;
  fill_topology(*t, "cube");
  ASSERT_TRUE(s.ingest_topology(*t));
  ASSERT_EQ(s.meshes().size(), 1u);
  EXPECT_EQ(s.image_file(), "/nonexistent.nii.gz");
  EXPECT_EQ(s.topology_generation(), 1u);

  wire::DeformationEncoder enc("cube", 4, 1, {3, true});
  wire::Sample<neurosim_Deformation> d;
  double u[12] = {0};
  u[3] = 0.002;  // vertex 1 moves 2 mm along x
  enc.encode(u, 12, 1, 0, *d);
  ASSERT_TRUE(s.ingest_deformation(*d));
  EXPECT_NEAR(s.max_displacement_m(), 0.002, 1e-9);
  u[3] = 0.003;
  enc.encode(u, 12, 2, 0, *d);  // a delta frame
  ASSERT_TRUE(s.ingest_deformation(*d));
  EXPECT_NEAR(s.max_displacement_m(), 0.003, 1e-6);
  EXPECT_EQ(s.counters().deformations, 2u);
  EXPECT_TRUE(warnings.empty());
}

TEST(ViewerState, MalformedSamplesAreCountedAndIgnored) {
  std::vector<std::string> warnings;
  nv::ViewerState s([&](const std::string& m) { warnings.push_back(m); });
  wire::Sample<neurosim_MeshTopology> t;
  fill_topology(*t, "cube");
  ASSERT_TRUE(s.ingest_topology(*t));

  // Topology with a tetrahedron naming vertex 9 of 4.
  wire::Sample<neurosim_MeshTopology> bad;
  fill_topology(*bad, "cube");
  bad->tetrahedra._buffer[3] = 9;
  EXPECT_FALSE(s.ingest_topology(*bad));
  EXPECT_EQ(s.counters().malformed_topology, 1u);
  ASSERT_FALSE(warnings.empty());
  EXPECT_NE(warnings.back().find("'cube'"), std::string::npos) << warnings.back();
  EXPECT_NE(warnings.back().find("tetrahedron 0"), std::string::npos) << warnings.back();
  EXPECT_EQ(s.mesh("cube")->tets[0][3], 3);  // the good topology is kept

  // Deformation with the wrong vertex count, and one with a NaN.
  wire::Sample<neurosim_Deformation> d;
  wire::set_string(d->mesh_id, "cube");
  d->encoding = neurosim_ENCODING_FULL;
  d->vertex_count = 5;
  std::vector<float> u(15, 0.0F);
  wire::assign(d->displacement_m, u);
  EXPECT_FALSE(s.ingest_deformation(*d));
  d->vertex_count = 4;
  u.assign(12, 0.0F);
  u[4] = std::numeric_limits<float>::quiet_NaN();
  wire::assign(d->displacement_m, u);
  EXPECT_FALSE(s.ingest_deformation(*d));
  EXPECT_EQ(s.counters().malformed_deformation, 2u);
  EXPECT_EQ(s.max_displacement_m(), 0.0);

  // ToolState with inf, ContactModel with NaN force.
  wire::Sample<neurosim_ToolState> ts;
  wire::set_string(ts->station_id, "omni-1");
  ts->orientation[0] = 1;
  ts->position_m[1] = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(s.ingest_tool(*ts));
  wire::Sample<neurosim_ContactModel> cm;
  wire::set_string(cm->station_id, "omni-1");
  cm->in_contact = true;
  cm->f0_n[2] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(s.ingest_contact(*cm));
  EXPECT_EQ(s.counters().malformed(), 5u);
  EXPECT_TRUE(s.tools().empty());

  // A deformation for a mesh not (yet) known waits, it is not malformed.
  wire::set_string(d->mesh_id, "other");
  EXPECT_FALSE(s.ingest_deformation(*d));
  EXPECT_EQ(s.counters().deformations_waiting, 1u);
}

TEST(ViewerState, ServerLivelinessCounts) {
  nv::ViewerState s;
  s.set_server_alive(true);
  s.set_server_alive(false);
  s.set_server_alive(true);
  EXPECT_EQ(s.counters().server_seen, 2u);
  EXPECT_EQ(s.counters().server_lost, 1u);
}

TEST(ViewerState, SimStatusTierAndRateAreKeptMalformedOnesIgnored) {
  std::vector<std::string> warnings;
  nv::ViewerState s([&](const std::string& m) { warnings.push_back(m); });
  EXPECT_FALSE(s.server_status().received);
  wire::Sample<neurosim_SimStatus> st;
  wire::set_string(st->server_id, "srv");
  wire::set_string(st->scene_name, "brain");
  st->tier = neurosim_TIER_NONLINEAR;
  st->tier_update_rate_hz = 12.5;
  st->step_rate_measured_hz = 999.0;
  EXPECT_TRUE(s.ingest_status(*st));
  EXPECT_TRUE(s.server_status().received);
  EXPECT_EQ(s.server_status().tier, "NONLINEAR");
  EXPECT_EQ(s.server_status().tier_update_rate_hz, 12.5);
  EXPECT_EQ(s.server_status().server_id, "srv");
  EXPECT_EQ(s.server_status().scene_name, "brain");
  EXPECT_FALSE(s.ingest_status(*st)) << "the same status again changes nothing";
  st->tier = neurosim_TIER_COROTATIONAL;
  st->tier_update_rate_hz = 3.0;
  EXPECT_TRUE(s.ingest_status(*st));
  EXPECT_EQ(s.server_status().tier, "COROTATIONAL");
  EXPECT_EQ(s.server_status().tier_update_rate_hz, 3.0);
  EXPECT_EQ(s.counters().statuses, 3u);

  // A tier this viewer does not know, a NaN and a negative rate: counted, the last good kept.
  st->tier = static_cast<neurosim_Tier>(7);
  EXPECT_FALSE(s.ingest_status(*st));
  st->tier = neurosim_TIER_NONLINEAR;
  st->tier_update_rate_hz = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(s.ingest_status(*st));
  st->tier_update_rate_hz = -1.0;
  EXPECT_FALSE(s.ingest_status(*st));
  EXPECT_EQ(s.counters().malformed_status, 3u);
  EXPECT_EQ(s.counters().malformed(), 3u);
  EXPECT_EQ(s.server_status().tier, "COROTATIONAL");
  EXPECT_EQ(s.server_status().tier_update_rate_hz, 3.0);
  ASSERT_EQ(warnings.size(), 3u);
  EXPECT_NE(warnings[0].find("SimStatus from server 'srv'"), std::string::npos) << warnings[0];
  EXPECT_NE(warnings[0].find("tier 7 (unknown)"), std::string::npos) << warnings[0];
}

// SimStatus max_strain and expected_force_error (the overlay's "strain 14 %: force error ~9 %"):
// kept; -1 (and any negative) means not measured / unknown; NaN is malformed.
TEST(ViewerState, SimStatusStrainAndExpectedErrorAreKept) {
  std::vector<std::string> warnings;
  nv::ViewerState s([&](const std::string& m) { warnings.push_back(m); });
  wire::Sample<neurosim_SimStatus> st;
  wire::set_string(st->server_id, "srv");
  st->tier = neurosim_TIER_LINEAR;
  st->max_strain = -1.0;
  st->expected_force_error = -1.0;
  EXPECT_TRUE(s.ingest_status(*st));
  EXPECT_EQ(s.server_status().max_strain, -1.0);
  EXPECT_EQ(s.server_status().expected_force_error, -1.0);
  st->max_strain = 0.14;
  st->expected_force_error = 0.09;
  EXPECT_TRUE(s.ingest_status(*st)) << "a new estimate is a change";
  EXPECT_EQ(s.server_status().max_strain, 0.14);
  EXPECT_EQ(s.server_status().expected_force_error, 0.09);
  st->expected_force_error = -7.0;
  EXPECT_TRUE(s.ingest_status(*st));
  EXPECT_EQ(s.server_status().expected_force_error, -1.0);
  st->max_strain = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(s.ingest_status(*st));
  EXPECT_EQ(s.counters().malformed_status, 1u);
  EXPECT_EQ(s.server_status().max_strain, 0.14);
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_NE(warnings[0].find("max_strain nan"), std::string::npos) << warnings[0];
}

// The error against the converged answer (SimStatus discretization_error_estimate,
// total_error_estimate) is kept, and the overlay's line names it and both parts; unknown parts
// say so and leave the total unknown.
TEST(ViewerState, TotalErrorAgainstTheConvergedAnswerIsShown) {
  nv::ViewerState s([](const std::string&) {});
  EXPECT_EQ(nv::error_text(s.server_status()), "") << "no SimStatus yet";
  wire::Sample<neurosim_SimStatus> st;
  wire::set_string(st->server_id, "srv");
  st->tier = neurosim_TIER_LINEAR;
  st->max_strain = 0.35;
  st->expected_force_error = 0.09;
  st->discretization_error_estimate = 0.056;
  st->total_error_estimate = 0.146;
  EXPECT_TRUE(s.ingest_status(*st));
  EXPECT_EQ(s.server_status().discretization_error_estimate, 0.056);
  EXPECT_EQ(s.server_status().total_error_estimate, 0.146);
  EXPECT_EQ(nv::error_text(s.server_status()),
            "error vs converged answer ~15 % (mesh + element ~6 %, tier ~9 %)");
  st->discretization_error_estimate = -1.0;
  st->total_error_estimate = -1.0;
  EXPECT_TRUE(s.ingest_status(*st)) << "unknown is a change";
  EXPECT_EQ(nv::error_text(s.server_status()),
            "error vs converged answer unknown (mesh + element unknown, tier ~9 %)");
  st->max_strain = -1.0;
  st->expected_force_error = -1.0;
  EXPECT_TRUE(s.ingest_status(*st));
  EXPECT_EQ(nv::error_text(s.server_status()),
            "error vs converged answer unknown (mesh + element unknown, tier not measured)");
  st->total_error_estimate = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(s.ingest_status(*st)) << "not finite: malformed";
}

TEST(ViewerOptions, GoodAndBadCommandLines) {
  bool help = false;
  const char* ok[] = {"v",        "--mode", "observe", "--headless", "--frames",       "3",
                      "--out",    "/tmp/x", "--size",  "320x240",    "--topic-prefix", "t_",
                      "--domain", "7"};
  const nv::ViewerOptions o = nv::parse_options(14, ok, help);
  EXPECT_EQ(o.mode, nv::Mode::Observe);
  EXPECT_TRUE(o.headless);
  EXPECT_EQ(o.frames, 3);
  EXPECT_EQ(o.width, 320);
  EXPECT_EQ(o.height, 240);
  EXPECT_EQ(o.domain, 7);
  EXPECT_EQ(o.topic_prefix, "t_");

  auto error_of = [&](std::vector<const char*> argv) {
    try {
      nv::parse_options(static_cast<int>(argv.size()), argv.data(), help);
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_NE(error_of({"v"}).find("--mode"), std::string::npos);
  EXPECT_NE(error_of({"v", "--mode", "xray"}).find("xray"), std::string::npos);
  EXPECT_NE(error_of({"v", "--mode", "navigation", "--frames", "3"}).find("--headless"),
            std::string::npos);
  EXPECT_NE(
      error_of({"v", "--mode", "navigation", "--headless", "--frames", "-1"}).find("--frames"),
      std::string::npos);
  EXPECT_NE(error_of({"v", "--mode", "navigation", "--size", "12"}).find("--size"),
            std::string::npos);
  EXPECT_NE(error_of({"v", "--mode", "navigation", "--domain", "999"}).find("--domain"),
            std::string::npos);
  EXPECT_NE(error_of({"v", "--mode", "navigation", "--bogus"}).find("--bogus"), std::string::npos);
  EXPECT_NE(error_of({"v", "--mode", "navigation", "--duration"}).find("needs a value"),
            std::string::npos);
}

TEST(ViewerOptions, SkullAndColourModes) {
  bool help = false;
  const char* defaults[] = {"v", "--mode", "navigation"};
  const nv::ViewerOptions d = nv::parse_options(3, defaults, help);
  EXPECT_EQ(d.skull, nv::SkullMode::Shown);
  EXPECT_EQ(d.colour, nv::ColourMode::Plain);
  const char* set[] = {"v", "--mode", "navigation", "--skull", "transparent", "--colour", "region"};
  const nv::ViewerOptions o = nv::parse_options(7, set, help);
  EXPECT_EQ(o.skull, nv::SkullMode::Transparent);
  EXPECT_EQ(o.colour, nv::ColourMode::Region);
  const char* hidden[] = {"v", "--mode", "observe", "--skull", "hidden"};
  EXPECT_EQ(nv::parse_options(5, hidden, help).skull, nv::SkullMode::Hidden);
  // The interactive key cycles through all three and back.
  EXPECT_EQ(nv::next(nv::SkullMode::Shown), nv::SkullMode::Transparent);
  EXPECT_EQ(nv::next(nv::SkullMode::Transparent), nv::SkullMode::Hidden);
  EXPECT_EQ(nv::next(nv::SkullMode::Hidden), nv::SkullMode::Shown);

  auto error_of = [&](std::vector<const char*> argv) {
    try {
      nv::parse_options(static_cast<int>(argv.size()), argv.data(), help);
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  const std::string bad_skull = error_of({"v", "--mode", "navigation", "--skull", "glass"});
  EXPECT_NE(bad_skull.find("--skull"), std::string::npos) << bad_skull;
  EXPECT_NE(bad_skull.find("glass"), std::string::npos) << bad_skull;
  const std::string bad_colour = error_of({"v", "--mode", "navigation", "--colour", "strain"});
  EXPECT_NE(bad_colour.find("--colour"), std::string::npos) << bad_colour;
  EXPECT_NE(error_of({"v", "--mode", "navigation", "--skull"}).find("needs a value"),
            std::string::npos);
  // --view-from: a direction (the demo's craniotomy axis); zero is refused, not the default.
  EXPECT_EQ(d.view_from, (std::array<double, 3>{0, 0, 0}));
  const char* from[] = {"v", "--mode", "navigation", "--view-from", "0.25,-0.95,-0.2"};
  EXPECT_EQ(nv::parse_options(5, from, help).view_from, (std::array<double, 3>{0.25, -0.95, -0.2}));
  EXPECT_NE(error_of({"v", "--mode", "navigation", "--view-from", "0,0,0"}).find("--view-from"),
            std::string::npos);
  EXPECT_NE(error_of({"v", "--mode", "navigation", "--view-from", "1,2"}).find("--view-from"),
            std::string::npos);
}

TEST(ViewerState, RigidMeshStaysOutOfTheDeformationPath) {
  std::vector<std::string> warnings;
  nv::ViewerState s([&](const std::string& m) { warnings.push_back(m); });
  wire::Sample<neurosim_MeshTopology> t;
  fill_topology(*t, "skull");
  wire::assign(t->tetrahedra, static_cast<const std::int32_t*>(nullptr), 0);
  t->rigid = true;
  ASSERT_TRUE(s.ingest_topology(*t));
  ASSERT_NE(s.mesh("skull"), nullptr);
  EXPECT_TRUE(s.mesh("skull")->rigid);
  EXPECT_TRUE(s.mesh("skull")->tets.empty());
  EXPECT_EQ(s.mesh("skull")->surface.size(), 4u);

  // A Deformation frame for a rigid mesh is malformed: counted, ignored, the mesh stays at rest.
  wire::DeformationEncoder enc("skull", 4, 1, {3, true});
  wire::Sample<neurosim_Deformation> d;
  double u[12] = {0};
  u[0] = 0.01;
  enc.encode(u, 12, 1, 0, *d);
  EXPECT_FALSE(s.ingest_deformation(*d));
  EXPECT_EQ(s.counters().malformed_deformation, 1u);
  EXPECT_EQ(s.counters().deformations, 0u);
  EXPECT_EQ(s.max_displacement_m(), 0.0);
  EXPECT_FALSE(s.mesh("skull")->has_deformation);
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_NE(warnings[0].find("rigid"), std::string::npos) << warnings[0];
  EXPECT_THROW(s.set_displacements("skull", std::vector<float>(12, 0.0F)), std::invalid_argument);

  // A rigid topology with tetrahedra (or without triangles) is refused, naming the mesh.
  wire::Sample<neurosim_MeshTopology> bad;
  fill_topology(*bad, "bad_skull");
  bad->rigid = true;
  EXPECT_FALSE(s.ingest_topology(*bad));
  EXPECT_EQ(s.counters().malformed_topology, 1u);
  EXPECT_NE(warnings.back().find("bad_skull"), std::string::npos) << warnings.back();
  EXPECT_EQ(s.mesh("bad_skull"), nullptr);
}

TEST(ViewerState, TetRegionsAreCheckedAndGiveSurfaceRegions) {
  std::vector<std::string> warnings;
  nv::ViewerState s([&](const std::string& m) { warnings.push_back(m); });
  // Two tetrahedra sharing face (1, 2, 3): vertex 0 on one side, vertex 4 on the other.
  wire::Sample<neurosim_MeshTopology> t;
  wire::set_string(t->mesh_id, "brain");
  const double v[] = {0, 0, 0, 0.01, 0, 0, 0, 0.01, 0, 0, 0, 0.01, 0.01, 0.01, 0.01};
  wire::assign(t->rest_vertices_m, v, 15);
  const std::int32_t tets[] = {0, 1, 2, 3, 4, 1, 3, 2};
  wire::assign(t->tetrahedra, tets, 8);
  const std::int32_t tris[] = {0, 2, 1, 0, 1, 3, 0, 3, 2, 4, 2, 1, 4, 1, 3, 4, 3, 2};
  wire::assign(t->surface_triangles, tris, 18);
  const std::uint8_t region[] = {1, 0};
  wire::assign(t->tet_region, region, 2);
  wire::reserve(t->region_names, 2);
  wire::set_string(t->region_names._buffer[0], "cerebrum");
  wire::set_string(t->region_names._buffer[1], "cerebellum");
  t->region_names._length = 2;
  ASSERT_TRUE(s.ingest_topology(*t));
  const nv::MeshState* m = s.mesh("brain");
  ASSERT_NE(m, nullptr);
  ASSERT_EQ(m->region_names.size(), 2u);
  EXPECT_EQ(m->region_names[1], "cerebellum");
  // Triangles 0-2 bound tetrahedron 0 (region 1), 3-5 tetrahedron 1 (region 0).
  EXPECT_EQ(nv::surface_regions(*m), (std::vector<int>{1, 1, 1, 0, 0, 0}));

  // A region index beyond the names, or a tet_region of the wrong length, is refused.
  const std::uint8_t out_of_range[] = {0, 2};
  wire::assign(t->tet_region, out_of_range, 2);
  EXPECT_FALSE(s.ingest_topology(*t));
  EXPECT_NE(warnings.back().find("tetrahedron 1 has region 2"), std::string::npos)
      << warnings.back();
  const std::uint8_t short_list[] = {0};
  wire::assign(t->tet_region, short_list, 1);
  EXPECT_FALSE(s.ingest_topology(*t));
  EXPECT_NE(warnings.back().find("tet_region has 1 entries for 2 tetrahedra"), std::string::npos)
      << warnings.back();
  EXPECT_EQ(s.counters().malformed_topology, 2u);
  // Without regions every triangle is -1.
  nv::MeshState plain = *m;
  plain.tet_region.clear();
  EXPECT_EQ(nv::surface_regions(plain), (std::vector<int>(6, -1)));
}
