// ObserverState and the protocol messages it builds: topology (JSON + geometry), frames (FULL and
// delta with their keyframe), stations, status; malformed samples counted, named and ignored.
#include "web/observer_state.hpp"

#include "idl/wire/deformation_codec.hpp"
#include "web_test_util.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>

namespace web = neurosim::web;
namespace wire = neurosim::wire;
namespace wt = neurosim::web::testing;

namespace {

std::vector<std::string> warnings;
web::ObserverState make_state() {
  warnings.clear();
  return web::ObserverState([](const std::string& m) { warnings.push_back(m); });
}

neurosim::common::Json json_of(const web::MessagePtr& m) {
  EXPECT_FALSE(m->binary);
  return neurosim::common::Json::parse(m->bytes);
}

}  // namespace

TEST(ObserverState, TopologyIsJsonThenOneGeometryPerMeshById) {
  auto s = make_state();
  wt::TestMesh a = wt::strip_mesh("zeta", 10), b = wt::strip_mesh("alpha", 4);
  ASSERT_TRUE(s.ingest_topology(**a.topology));
  const web::TopologyPtr t = s.ingest_topology(**b.topology);
  ASSERT_TRUE(t);
  EXPECT_EQ(t->generation, 2U);
  EXPECT_EQ(t->meshes, 2U);
  ASSERT_EQ(t->messages.size(), 3U);
  const auto head = json_of(t->messages[0]);
  EXPECT_EQ(head["type"], "topology");
  EXPECT_EQ(head["scene"], "test_scene");
  EXPECT_EQ(head["meshes"][0]["id"], "alpha");  // sorted by id: alpha is index 0
  EXPECT_EQ(head["meshes"][0]["vertices"], 4 * 2);
  EXPECT_EQ(head["meshes"][1]["id"], "zeta");
  EXPECT_EQ(head["meshes"][1]["triangles"], 2 * (10 - 1));
  // Geometry of index 1 (zeta): header, float32 rest positions, uint32 triangles.
  const std::string& g = t->messages[2]->bytes;
  ASSERT_TRUE(t->messages[2]->binary);
  ASSERT_EQ(g.size(), web::kGeometryHeaderBytes + 12 * 20 + 12 * 18);
  EXPECT_EQ(static_cast<std::uint8_t>(g[0]), web::kKindMeshGeometry);
  std::uint16_t index = 0;
  std::uint32_t generation = 0;
  float x3 = 0, y3 = 0;
  std::uint32_t last_id = 0;
  std::memcpy(&index, &g[2], 2);
  std::memcpy(&generation, &g[12], 4);
  std::memcpy(&x3, &g[web::kGeometryHeaderBytes + 36], 4);  // vertex 3
  std::memcpy(&y3, &g[web::kGeometryHeaderBytes + 40], 4);
  std::memcpy(&last_id, &g[g.size() - 4], 4);  // last id of the last triangle
  EXPECT_EQ(index, 1);
  EXPECT_EQ(generation, 2U);
  EXPECT_FLOAT_EQ(x3, static_cast<float>(wt::strip_vertex(3)[0]));
  EXPECT_FLOAT_EQ(y3, static_cast<float>(wt::strip_vertex(3)[1]));
  EXPECT_EQ(last_id, 19U);
  EXPECT_TRUE(warnings.empty());
}

TEST(ObserverState, FramesFullThenDeltasCarryTheirKeyframe) {
  auto s = make_state();
  wt::TestMesh m = wt::strip_mesh("brain", 50);
  s.ingest_topology(**m.topology);
  wire::DeformationEncoder enc("brain", m.vertices, 0, {});
  wire::Sample<neurosim_Deformation> d;
  const auto u0 = wt::displacement(m.vertices, 0.001);
  enc.encode(u0.data(), u0.size(), 1, 100, *d);
  const web::FramePtr full = s.ingest_deformation(*d);
  ASSERT_TRUE(full);
  EXPECT_TRUE(full->full);
  EXPECT_EQ(full->message.bytes.size(), web::kFrameHeaderBytes + 4 * 3 * m.vertices);
  const auto u1 = wt::displacement(m.vertices, 0.002);
  enc.encode(u1.data(), u1.size(), 2, 200, *d);
  const web::FramePtr delta = s.ingest_deformation(*d);
  ASSERT_TRUE(delta);
  EXPECT_FALSE(delta->full);
  EXPECT_EQ(delta->base, full);
  EXPECT_EQ(delta->full_serial, full->full_serial);
  EXPECT_EQ(delta->message.bytes.size(), web::kFrameHeaderBytes + 2 * 3 * m.vertices);
  const web::FrameHeader h =
      web::parse_frame_header(delta->message.bytes.data(), delta->message.bytes.size());
  EXPECT_EQ(h.encoding, web::kEncodingDelta);
  EXPECT_EQ(h.frame, 1U);
  EXPECT_EQ(h.base_frame, 0U);
  EXPECT_EQ(h.server_time_ns, 200);
  EXPECT_EQ(h.vertex_count, m.vertices);
  // Decoding as the page does gives the displacement back within the quantization step.
  std::vector<float> u(3 * m.vertices);
  const char* fp = full->message.bytes.data() + web::kFrameHeaderBytes;
  const char* dp = delta->message.bytes.data() + web::kFrameHeaderBytes;
  for (std::size_t i = 0; i < u.size(); ++i) {
    float base = 0;
    std::int16_t q = 0;
    std::memcpy(&base, fp + 4 * i, 4);
    std::memcpy(&q, dp + 2 * i, 2);
    EXPECT_NEAR(base + h.delta_scale_m * q, u1[i], h.delta_scale_m) << "component " << i;
  }
  EXPECT_EQ(s.counters().frames, 2U);
}

TEST(ObserverState, DeltaWithoutItsFullFrameWaits) {
  auto s = make_state();
  wt::TestMesh m = wt::strip_mesh("brain", 5);
  wire::DeformationEncoder enc("brain", m.vertices, 0, {});
  wire::Sample<neurosim_Deformation> d;
  const auto u = wt::displacement(m.vertices, 0.001);
  enc.encode(u.data(), u.size(), 1, 1, *d);
  EXPECT_FALSE(s.ingest_deformation(*d));  // no topology yet
  s.ingest_topology(**m.topology);
  enc.encode(u.data(), u.size(), 2, 2, *d);  // a delta: its FULL frame came before the topology
  EXPECT_FALSE(s.ingest_deformation(*d));
  EXPECT_EQ(s.counters().frames_waiting, 2U);
  EXPECT_EQ(s.counters().malformed_frame, 0U);
}

TEST(ObserverState, NewTopologyForgetsOldKeyframes) {
  auto s = make_state();
  wt::TestMesh m = wt::strip_mesh("brain", 5);
  s.ingest_topology(**m.topology);
  wire::DeformationEncoder enc("brain", m.vertices, 0, {});
  wire::Sample<neurosim_Deformation> d;
  const auto u = wt::displacement(m.vertices, 0.001);
  enc.encode(u.data(), u.size(), 1, 1, *d);
  ASSERT_TRUE(s.ingest_deformation(*d));
  s.ingest_topology(**m.topology);  // a restarted server sends its topology again
  enc.encode(u.data(), u.size(), 2, 2, *d);
  EXPECT_FALSE(s.ingest_deformation(*d));  // the delta's FULL frame belongs to the old generation
}

TEST(ObserverState, MalformedSamplesAreNamedAndIgnored) {
  auto s = make_state();
  wt::TestMesh m = wt::strip_mesh("brain", 5);
  wire::Sample<neurosim_MeshTopology> bad;
  wire::set_string(bad->mesh_id, "broken");
  const double v[] = {0, 0, 0, 1, 0, 0};
  wire::assign(bad->rest_vertices_m, v, 6);
  const std::int32_t tri[] = {0, 1, 7};
  wire::assign(bad->surface_triangles, tri, 3);
  EXPECT_FALSE(s.ingest_topology(*bad));
  ASSERT_EQ(warnings.size(), 1U);
  EXPECT_NE(warnings[0].find("MeshTopology 'broken': surface triangle 0 has vertex 7 outside 0..1"),
            std::string::npos);

  s.ingest_topology(**m.topology);
  wire::Sample<neurosim_Deformation> d;
  wire::set_string(d->mesh_id, "brain");
  d->encoding = neurosim_ENCODING_FULL;
  d->vertex_count = m.vertices + 1;
  d->frame = 7;
  EXPECT_FALSE(s.ingest_deformation(*d));
  EXPECT_NE(
      warnings.back().find("Deformation 'brain' frame 7: vertex_count 11, the topology has 10"),
      std::string::npos);
  d->vertex_count = m.vertices;
  const std::int32_t seven = 7;  // an encoding this bridge does not know
  std::memcpy(&d->encoding, &seven, sizeof seven);
  EXPECT_FALSE(s.ingest_deformation(*d));
  EXPECT_NE(warnings.back().find("Deformation 'brain' frame 7: unknown encoding 7"),
            std::string::npos);
  d->encoding = neurosim_ENCODING_FULL;
  std::vector<float> u(3 * m.vertices, 0.0F);
  u[4] = std::nanf("");
  wire::assign(d->displacement_m, u);
  EXPECT_FALSE(s.ingest_deformation(*d));
  EXPECT_NE(warnings.back().find("vertex 1 has a non-finite displacement"), std::string::npos);

  wire::Sample<neurosim_ContactModel> c;
  wire::set_string(c->station_id, "st");
  c->f0_n[1] = std::nan("");
  EXPECT_FALSE(s.ingest_contact(*c));
  wire::Sample<neurosim_SimStatus> st;
  const std::int32_t nine = 9;  // a tier this bridge does not know, as it would come off the wire
  std::memcpy(&st->tier, &nine, sizeof nine);
  EXPECT_FALSE(s.ingest_status(*st));
  EXPECT_NE(warnings.back().find("tier 9 (unknown)"), std::string::npos);
  const auto& k = s.counters();
  EXPECT_EQ(k.malformed_topology, 1U);
  EXPECT_EQ(k.malformed_frame, 3U);
  EXPECT_EQ(k.malformed_contact, 1U);
  EXPECT_EQ(k.malformed_status, 1U);
}

TEST(ObserverState, StationsAndStatusMessages) {
  auto s = make_state();
  wire::Sample<neurosim_ContactModel> c;
  wire::set_string(c->station_id, "omni-1");
  wire::set_string(c->contact_mesh_id, "brain");
  c->in_contact = true;
  c->f0_n[0] = 0.3;
  c->f0_n[2] = -0.4;
  c->x0_position_m[0] = 0.1;
  c->x0_orientation[0] = 1;  // identity: shaft along +z
  ASSERT_TRUE(s.ingest_contact(*c));
  auto j = json_of(s.stations_message());
  EXPECT_EQ(j["type"], "stations");
  EXPECT_EQ(j["stations"][0]["id"], "omni-1");
  EXPECT_NEAR(j["stations"][0]["force_magnitude_n"].get<double>(), 0.5, 1e-12);
  EXPECT_EQ(j["stations"][0]["axis"][2], 1.0);
  EXPECT_EQ(j["stations"][0]["mesh"], "brain");
  c->in_contact = false;  // out of contact the force shown is zero whatever f0 holds
  s.ingest_contact(*c);
  EXPECT_EQ(json_of(s.stations_message())["stations"][0]["force_magnitude_n"], 0.0);
  EXPECT_TRUE(s.remove_station("omni-1"));
  EXPECT_TRUE(json_of(s.stations_message())["stations"].empty());

  EXPECT_TRUE(s.set_server_alive(true));
  EXPECT_FALSE(s.set_server_alive(true));
  wire::Sample<neurosim_SimStatus> st;
  wire::set_string(st->server_id, "srv");
  wire::set_string(st->scene_name, "cube_cylinder");
  st->tier = neurosim_TIER_NONLINEAR;
  st->tier_update_rate_hz = 44.5;
  st->step_rate_measured_hz = 999;
  st->step_time_p50_us = std::nan("");  // before the first steps
  st->max_strain = 0.14;
  st->expected_force_error = -1;  // unknown
  st->discretization_error_estimate = 0.056;
  st->total_error_estimate = -1;  // unknown: the tier's part is
  ASSERT_TRUE(s.ingest_status(*st));
  web::BridgeRates r;
  r.deformation_hz = 30;
  r.clients = 2;
  r.max_clients = 16;
  j = json_of(s.status_message(r));
  EXPECT_EQ(j["type"], "status");
  EXPECT_EQ(j["server_alive"], true);
  EXPECT_EQ(j["server"]["tier"], "NONLINEAR");
  EXPECT_EQ(j["server"]["scene"], "cube_cylinder");
  EXPECT_EQ(j["server"]["tier_update_rate_hz"], 44.5);
  EXPECT_TRUE(j["server"]["step_time_p50_us"].is_null());
  EXPECT_EQ(j["server"]["max_strain"], 0.14);
  EXPECT_EQ(j["server"]["expected_force_error"], -1.0);
  EXPECT_EQ(j["server"]["discretization_error_estimate"], 0.056);
  EXPECT_EQ(j["server"]["total_error_estimate"], -1.0);
  EXPECT_EQ(j["bridge"]["clients"], 2);
  EXPECT_EQ(j["bridge"]["deformation_hz"], 30.0);
  s.set_server_alive(false);
  EXPECT_EQ(json_of(s.status_message(r))["server_alive"], false);
  EXPECT_EQ(s.counters().server_lost, 1U);
}

TEST(ObserverState, ForceColourIsThePapersRule) {
  auto c = web::force_colour(0.0);
  EXPECT_DOUBLE_EQ(c[0], 0.2);
  EXPECT_DOUBLE_EQ(c[1], 0.2);
  c = web::force_colour(0.1);
  EXPECT_DOUBLE_EQ(c[0], 0.30000000000000004);
  EXPECT_DOUBLE_EQ(c[1], 0.1);
  c = web::force_colour(-2.0, 0.25);  // |F| / 0.25 N = 8: fully red
  EXPECT_DOUBLE_EQ(c[0], 1.0);
  EXPECT_DOUBLE_EQ(c[2], 0.0);
}
