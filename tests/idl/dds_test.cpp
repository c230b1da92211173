// neurosim::wire over Cyclone DDS (loopback): typed round trips, the QoS contracts of qos.hpp
// (keep-last 1, transient-local late joiner, liveliness of SimStatus), dispose, waitset wake,
// the CYCLONEDDS_URI rule, and errors.
#include "idl/wire/dds.hpp"
#include "tests/idl/wire_test_util.hpp"
#include "test_support.hpp"

#include <dds/ddsi/ddsi_serdata.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <map>
#include <random>
#include <thread>

namespace ns = neurosim::wire;
using neurosim::wire::testing::seconds_since;
using neurosim::wire::testing::take_until;
using neurosim::wire::testing::unique_topic;

namespace {

constexpr dds_duration_t kMatchTimeout = DDS_SECS(5);

// Everything one typed test needs: participant, topic, writer, reader, waitset on the reader.
template <class T>
struct Loop {
  ns::Participant pp;
  ns::Topic<T> topic{pp, unique_topic(ns::TopicTraits<T>::name)};
  ns::Writer<T> writer{make_writer()};
  ns::Reader<T> reader{pp, topic};
  ns::Waitset ws{pp};
  // A ToolState writer is one station's, in its partition (the reader's wildcard matches it).
  ns::Writer<T> make_writer() {
    if constexpr (ns::TopicTraits<T>::profile == ns::Profile::ToolState)
      return ns::Writer<T>(pp, topic, "omni-1");
    else
      return ns::Writer<T>(pp, topic);
  }
  Loop() {
    ws.attach_data(reader, 1);
    EXPECT_TRUE(writer.wait_for_readers(1, kMatchTimeout));
  }
  // Writes s and returns a copy of the first valid sample taken (key fields compared by caller).
  template <class Check>
  void round_trip(const T& s, Check check) {
    writer.write(s);
    bool got = take_until(reader, ws, DDS_SECS(5), [&](const ns::Batch<T>& b) {
      const T* d = b.newest();
      if (d) check(*d);
      return d != nullptr;
    });
    EXPECT_TRUE(got) << "no sample on " << topic.name();
  }
};

std::mt19937_64 rng(12345);
double rnd() { return std::uniform_real_distribution<double>(-1, 1)(rng); }

}  // namespace

TEST(wire_dds, ToolStateRoundTrip) {
  Loop<neurosim_ToolState> l;
  ns::Sample<neurosim_ToolState> s;
  ns::set_string(s->station_id, "omni-1");
  ns::set_string(s->tool_id, "probe");
  for (double& x : s->position_m) x = rnd();
  for (double& x : s->orientation) x = rnd();
  for (double& x : s->velocity_m_per_s) x = rnd();
  s->buttons = 0x5;
  s->sequence_number = 987654321012ull;
  s->source_time_ns = 1700000000123456789ll;
  l.round_trip(*s, [&](const neurosim_ToolState& d) {
    EXPECT_STREQ(d.station_id, "omni-1");
    EXPECT_STREQ(d.tool_id, "probe");
    for (int i = 0; i < 3; ++i) EXPECT_EQ(d.position_m[i], s->position_m[i]);
    for (int i = 0; i < 4; ++i) EXPECT_EQ(d.orientation[i], s->orientation[i]);
    for (int i = 0; i < 3; ++i) EXPECT_EQ(d.velocity_m_per_s[i], s->velocity_m_per_s[i]);
    EXPECT_EQ(d.buttons, s->buttons);
    EXPECT_EQ(d.sequence_number, s->sequence_number);
    EXPECT_EQ(d.source_time_ns, s->source_time_ns);
  });
}

TEST(wire_dds, ContactModelRoundTrip) {
  Loop<neurosim_ContactModel> l;
  ns::Sample<neurosim_ContactModel> s;
  ns::set_string(s->station_id, "omni-2");
  ns::set_string(s->contact_mesh_id, "brain");
  s->tool_sequence = 42;
  s->tool_source_time_ns = 77;
  for (double& x : s->x0_position_m) x = rnd();
  for (double& x : s->x0_orientation) x = rnd();
  for (double& x : s->f0_n) x = rnd();
  for (double& x : s->stiffness_n_per_m) x = 100 * rnd();
  for (double& x : s->normal) x = rnd();
  s->in_contact = true;
  s->validity_radius_m = 0.002;
  s->server_step = 1234;
  s->server_time_ns = 99;
  s->tool_sample_rejected = true;
  l.round_trip(*s, [&](const neurosim_ContactModel& d) {
    EXPECT_STREQ(d.station_id, "omni-2");
    EXPECT_STREQ(d.contact_mesh_id, "brain");
    EXPECT_EQ(d.tool_sequence, 42u);
    EXPECT_EQ(d.tool_source_time_ns, 77);
    for (int i = 0; i < 9; ++i) EXPECT_EQ(d.stiffness_n_per_m[i], s->stiffness_n_per_m[i]);
    for (int i = 0; i < 3; ++i) EXPECT_EQ(d.f0_n[i], s->f0_n[i]);
    for (int i = 0; i < 3; ++i) EXPECT_EQ(d.x0_position_m[i], s->x0_position_m[i]);
    for (int i = 0; i < 4; ++i) EXPECT_EQ(d.x0_orientation[i], s->x0_orientation[i]);
    for (int i = 0; i < 3; ++i) EXPECT_EQ(d.normal[i], s->normal[i]);
    EXPECT_TRUE(d.in_contact);
    EXPECT_TRUE(d.tool_sample_rejected);
    EXPECT_EQ(d.validity_radius_m, 0.002);
    EXPECT_EQ(d.server_step, 1234u);
    EXPECT_EQ(d.server_time_ns, 99);
  });
}

TEST(wire_dds, DeformationRoundTripBrainSized) {
  Loop<neurosim_Deformation> l;
  const std::size_t nv = 5400;  // about the brain mesh's vertex count (~5k, the paper's size)
  std::vector<float> u(3 * nv);
  for (float& x : u) x = static_cast<float>(1e-3 * rnd());
  std::vector<short> q(3 * nv);
  for (short& x : q) x = static_cast<short>(32767 * rnd());
  ns::Sample<neurosim_Deformation> s;
  ns::set_string(s->mesh_id, "brain");
  s->frame = 7;
  s->base_frame = 5;
  s->encoding = neurosim_ENCODING_QUANTIZED_DELTA;
  s->vertex_count = nv;
  ns::assign(s->displacement_m, u);
  ns::assign(s->delta_q, q);
  s->delta_scale_m = 1e-7f;
  l.round_trip(*s, [&](const neurosim_Deformation& d) {
    EXPECT_STREQ(d.mesh_id, "brain");
    EXPECT_EQ(d.frame, 7u);
    EXPECT_EQ(d.base_frame, 5u);
    EXPECT_EQ(d.encoding, neurosim_ENCODING_QUANTIZED_DELTA);
    EXPECT_EQ(ns::to_vector(d.displacement_m), u);
    EXPECT_EQ(ns::to_vector(d.delta_q), q);
    EXPECT_EQ(d.delta_scale_m, 1e-7f);
  });
  // The reader reuses its buffers: a shorter second frame must come back with its own length.
  u.resize(30);
  ns::assign(s->displacement_m, u);
  s->delta_q._length = 0;
  s->frame = 8;
  l.round_trip(*s, [&](const neurosim_Deformation& d) {
    EXPECT_EQ(d.frame, 8u);
    EXPECT_EQ(ns::to_vector(d.displacement_m), u);
    EXPECT_EQ(d.delta_q._length, 0u);
  });
}

TEST(wire_dds, MeshTopologyRoundTrip) {
  Loop<neurosim_MeshTopology> l;
  ns::Sample<neurosim_MeshTopology> s;
  ns::set_string(s->mesh_id, "artery");
  s->revision = 3;
  ns::set_string(s->scene_name, "brain_artery");
  const std::vector<double> x = {0, 0, 0, 1e-3, 0, 0, 0, 1e-3, 0, 0, 0, 1e-3};
  const std::vector<int32_t> tets = {0, 1, 2, 3};
  const std::vector<int32_t> tris = {0, 2, 1, 0, 1, 3, 1, 2, 3, 0, 3, 2};
  ns::assign(s->rest_vertices_m, x);
  ns::assign(s->tetrahedra, tets);
  ns::assign(s->surface_triangles, tris);
  ns::set_string(s->material_name, "vessel");
  s->youngs_modulus_pa = 2.5e5;
  s->poisson_ratio = 0.45;
  s->priority = 2;
  ns::set_string(s->volume_image_file, "/usr/share/mricron/templates/ch2bet.nii.gz");
  s->volume_image_unit_m = 1e-3;
  ns::set_string(s->provenance, "generated tube along the MCA course");
  l.round_trip(*s, [&](const neurosim_MeshTopology& d) {
    EXPECT_STREQ(d.mesh_id, "artery");
    EXPECT_EQ(d.revision, 3u);
    EXPECT_EQ(ns::get_string(d.scene_name), "brain_artery");
    EXPECT_EQ(ns::to_vector(d.rest_vertices_m), x);
    EXPECT_EQ(ns::to_vector(d.tetrahedra), tets);
    EXPECT_EQ(ns::to_vector(d.surface_triangles), tris);
    EXPECT_EQ(ns::get_string(d.material_name), "vessel");
    EXPECT_EQ(d.youngs_modulus_pa, 2.5e5);
    EXPECT_EQ(d.poisson_ratio, 0.45);
    EXPECT_EQ(d.priority, 2);
    EXPECT_EQ(ns::get_string(d.volume_image_file), "/usr/share/mricron/templates/ch2bet.nii.gz");
    EXPECT_EQ(d.volume_image_unit_m, 1e-3);
    EXPECT_EQ(ns::get_string(d.provenance), "generated tube along the MCA course");
  });
}

TEST(wire_dds, SimStatusRoundTrip) {
  Loop<neurosim_SimStatus> l;
  ns::Sample<neurosim_SimStatus> s;
  ns::set_string(s->server_id, "server-A");
  ns::set_string(s->scene_name, "cube_cylinder");
  ns::set_string(s->effects, "tool_contact,coupling");
  s->tier = neurosim_TIER_COROTATIONAL;
  s->step_rate_target_hz = 1000;
  s->step_time_p50_us = 12.5;
  s->step_time_p99_us = 80.25;
  s->steps = 123456;
  s->max_stations = 8;
  std::vector<neurosim_StationStatus> st(3);
  for (std::size_t i = 0; i < st.size(); ++i) {
    ns::set_string(st[i].station_id, "omni-" + std::to_string(i));
    st[i].alive = i != 1;
    st[i].samples_accepted = 1000 + i;
    st[i].samples_rejected_jump = i;
  }
  ns::assign(s->stations, st);
  s->samples_rejected_nonfinite = 4;
  l.round_trip(*s, [&](const neurosim_SimStatus& d) {
    EXPECT_STREQ(d.server_id, "server-A");
    EXPECT_EQ(ns::get_string(d.effects), "tool_contact,coupling");
    EXPECT_EQ(d.tier, neurosim_TIER_COROTATIONAL);
    EXPECT_EQ(d.step_time_p99_us, 80.25);
    EXPECT_EQ(d.steps, 123456u);
    ASSERT_EQ(d.stations._length, 3u);
    for (std::size_t i = 0; i < 3; ++i) {
      EXPECT_EQ(std::string(d.stations._buffer[i].station_id), "omni-" + std::to_string(i));
      EXPECT_EQ(d.stations._buffer[i].alive, i != 1);
      EXPECT_EQ(d.stations._buffer[i].samples_accepted, 1000 + i);
      EXPECT_EQ(d.stations._buffer[i].samples_rejected_jump, i);
    }
    EXPECT_EQ(d.samples_rejected_nonfinite, 4u);
  });
}

// Keep-last 1 per key: a slow reader sees only the newest pose of each station.
TEST(wire_dds, KeepLastOneGivesNewestToolStatePerStation) {
  Loop<neurosim_ToolState> l;
  ns::Sample<neurosim_ToolState> s;
  for (std::uint64_t k = 1; k <= 50; ++k) {
    for (const char* station : {"a", "b"}) {
      ns::set_string(s->station_id, station);
      s->sequence_number = k + (station[0] == 'b' ? 1000 : 0);
      s->position_m[0] = static_cast<double>(k);
      l.writer.write(*s);
    }
  }
  // Let everything arrive, then take once.
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  auto b = l.reader.take();
  std::size_t valid = 0;
  for (const auto& rx : b) {
    if (!rx.valid()) continue;
    ++valid;
    EXPECT_EQ(rx.data.position_m[0], 50.0);
  }
  EXPECT_EQ(valid, 2u);
  ASSERT_NE(b.newest("a"), nullptr);
  ASSERT_NE(b.newest("b"), nullptr);
  EXPECT_EQ(b.newest("a")->sequence_number, 50u);
  EXPECT_EQ(b.newest("b")->sequence_number, 1050u);
  EXPECT_EQ(b.newest("c"), nullptr);
  EXPECT_TRUE(l.reader.take().empty());
}

// Transient-local: a viewer joining after the server published gets the topology anyway.
TEST(wire_dds, LateJoinerGetsMeshTopology) {
  ns::Participant server;
  const std::string name = unique_topic(ns::TopicTraits<neurosim_MeshTopology>::name);
  ns::Topic<neurosim_MeshTopology> st(server, name);
  ns::Writer<neurosim_MeshTopology> w(server, st);
  ns::Sample<neurosim_MeshTopology> s;
  for (const char* id : {"brain", "artery"}) {
    ns::set_string(s->mesh_id, id);
    ns::assign(s->tetrahedra, std::vector<int32_t>{0, 1, 2, 3});
    s->revision = 1;
    w.write(*s);
    s->revision = 2;  // keep-last 1: the late joiner must get this one only
    w.write(*s);
  }
  ASSERT_EQ(w.matched_readers(), 0u);  // nobody was there when it was written

  ns::Participant viewer;
  ns::Topic<neurosim_MeshTopology> vt(viewer, name);
  ns::Reader<neurosim_MeshTopology> r(viewer, vt);
  ns::Waitset ws(viewer);
  ws.attach_data(r, 1);
  std::map<std::string, std::uint32_t> got;
  take_until(r, ws, DDS_SECS(5), [&](const ns::Batch<neurosim_MeshTopology>& b) {
    for (const auto& rx : b)
      if (rx.valid()) got[std::string(rx.key())] = rx.data.revision;
    return got.size() == 2;
  });
  ASSERT_EQ(got.size(), 2u);
  EXPECT_EQ(got["brain"], 2u);
  EXPECT_EQ(got["artery"], 2u);
}

// A station that deletes its writer (autodispose on) shows as disposed at the server.
TEST(wire_dds, ToolStateWriterGoneDisposesStation) {
  ns::Participant pp;
  ns::Topic<neurosim_ToolState> t(pp, unique_topic("ToolState"));
  ns::Reader<neurosim_ToolState> r(pp, t);
  ns::Waitset ws(pp);
  ws.attach_data(r, 1);
  {
    ns::Writer<neurosim_ToolState> w(pp, t, "leaving");
    ASSERT_TRUE(w.wait_for_readers(1, kMatchTimeout));
    ns::Sample<neurosim_ToolState> s;
    ns::set_string(s->station_id, "leaving");
    s->sequence_number = 1;
    w.write(*s);
    ASSERT_TRUE(take_until(r, ws, DDS_SECS(5),
                           [](const auto& b) { return b.newest("leaving") != nullptr; }));
  }
  bool disposed = false;
  take_until(r, ws, DDS_SECS(5), [&](const ns::Batch<neurosim_ToolState>& b) {
    for (const auto& rx : b)
      if (rx.disposed() && rx.key() == "leaving" && !rx.valid()) disposed = true;
    return disposed;
  });
  EXPECT_TRUE(disposed);
}

// SimStatus (autodispose off): the server going away is seen through liveliness_changed within
// about a second, and the instance becomes "no writers", not "disposed".
TEST(wire_dds, SimStatusWriterGoneSeenThroughLiveliness) {
  ns::Participant client;
  const std::string name = unique_topic("SimStatus");
  ns::Topic<neurosim_SimStatus> ct(client, name);
  ns::Reader<neurosim_SimStatus> r(client, ct);
  ns::Waitset ws(client);
  ws.attach_liveliness(r, 2);
  ws.attach_data(r, 1);

  auto server = std::make_unique<ns::Participant>();
  {
    ns::Topic<neurosim_SimStatus> stopic(*server, name);
    ns::Writer<neurosim_SimStatus> w(*server, stopic);
    ASSERT_TRUE(w.wait_for_readers(1, kMatchTimeout));
    ns::Sample<neurosim_SimStatus> s;
    ns::set_string(s->server_id, "srv");
    w.write(*s);
    ASSERT_TRUE(take_until(r, ws, DDS_SECS(5),
                           [](const auto& b) { return b.newest("srv") != nullptr; }));
  }
  // Writer deleted inside the block above, then its participant.
  const auto t0 = std::chrono::steady_clock::now();
  server.reset();
  ns::Liveliness live = r.liveliness();
  while (live.alive_count > 0 && seconds_since(t0) < 5) {
    ws.wait(DDS_MSECS(100));
    live = r.liveliness();
  }
  const double dt = seconds_since(t0);
  EXPECT_EQ(live.alive_count, 0u);
  EXPECT_LT(dt, 1.0) << "server loss seen after " << dt << " s";

  bool no_writers = false, disposed = false;
  take_until(r, ws, DDS_SECS(2), [&](const ns::Batch<neurosim_SimStatus>& b) {
    for (const auto& rx : b) {
      no_writers |= rx.no_writers();
      disposed |= rx.disposed();
    }
    return no_writers;
  });
  EXPECT_TRUE(no_writers);
  EXPECT_FALSE(disposed) << "SimStatus writers must not autodispose";
}

// Same across processes: a SimStatus writer killed with SIGKILL (no goodbye) is seen within ~1 s.
TEST(wire_dds, KilledServerProcessSeenWithinOneSecond) {
  const std::string name = unique_topic("SimStatus");
  const auto child_bin = neurosim::testing::bin_dir() / "wire_test_sim_status_child";
  ASSERT_TRUE(std::filesystem::exists(child_bin)) << child_bin;
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    execl(child_bin.c_str(), child_bin.c_str(), name.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  ns::Participant client;
  ns::Topic<neurosim_SimStatus> t(client, name);
  ns::Reader<neurosim_SimStatus> r(client, t);
  ns::Waitset ws(client);
  ws.attach_data(r, 1);
  ws.attach_liveliness(r, 2);
  const bool got = take_until(r, ws, DDS_SECS(10), [](const ns::Batch<neurosim_SimStatus>& b) {
    return b.newest("child") != nullptr;
  });
  const bool alive = r.liveliness().alive_count == 1;
  kill(pid, SIGKILL);
  const auto t0 = std::chrono::steady_clock::now();
  int status = 0;
  waitpid(pid, &status, 0);
  ASSERT_TRUE(got) << "no SimStatus from the child process";
  EXPECT_TRUE(alive);
  ns::Liveliness live = r.liveliness();
  while (live.alive_count > 0 && seconds_since(t0) < 5) {
    ws.wait(DDS_MSECS(100));
    live = r.liveliness();
  }
  const double dt = seconds_since(t0);
  EXPECT_EQ(live.alive_count, 0u);
  EXPECT_LT(dt, 1.0) << "killed server seen after " << dt << " s";
  std::printf("killed SimStatus writer seen not alive after %.3f s\n", dt);
}

TEST(wire_dds, WaitsetWakesForShutdown) {
  ns::Participant pp;
  ns::Topic<neurosim_ToolState> t(pp, unique_topic("ToolState"));
  ns::Reader<neurosim_ToolState> r(pp, t);
  ns::Waitset ws(pp);
  ws.attach_data(r, 1);
  EXPECT_TRUE(ws.wait(DDS_MSECS(20)).timed_out());
  const auto t0 = std::chrono::steady_clock::now();
  std::thread waker([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    ws.wake();
  });
  const auto res = ws.wait(DDS_SECS(10));
  waker.join();
  EXPECT_TRUE(res.woken);
  EXPECT_EQ(res.count, 0u);
  EXPECT_LT(seconds_since(t0), 2.0);
  // The guard was reset: the next wait times out again.
  EXPECT_TRUE(ws.wait(DDS_MSECS(20)).timed_out());
  EXPECT_THROW(ws.attach_data(r, ns::Waitset::kWakeToken), std::invalid_argument);
}

TEST(wire_dds, RefusesToStartWithoutConfig) {
  const std::string saved = std::getenv("CYCLONEDDS_URI") ? std::getenv("CYCLONEDDS_URI") : "";
  unsetenv("CYCLONEDDS_URI");
  try {
    ns::Participant pp;
    ADD_FAILURE() << "Participant started without CYCLONEDDS_URI";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("CYCLONEDDS_URI"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("loopback.xml"), std::string::npos) << e.what();
  }
  if (!saved.empty()) setenv("CYCLONEDDS_URI", saved.c_str(), 1);
}

TEST(wire_dds, ErrorsNameWhatWasBeingDone) {
  ns::Participant pp;
  try {
    ns::Topic<neurosim_ToolState> t(pp, "bad topic name!");
    ADD_FAILURE() << "bad topic name accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("create topic bad topic name!"), std::string::npos)
        << e.what();
  }
  ns::Sample<neurosim_ToolState> s;
  EXPECT_THROW(ns::set_string(s->station_id, std::string(65, 'x'), "station_id"),
               std::invalid_argument);
  EXPECT_NO_THROW(ns::set_string(s->station_id, std::string(64, 'x'), "station_id"));
}

// Serialized sizes of Deformation frames for the brain mesh (5.4k vertices), for the report.
TEST(wire_dds, DeformationSampleSizes) {
  Loop<neurosim_Deformation> l;
  const std::size_t nv = 5400;
  ns::Sample<neurosim_Deformation> s;
  ns::set_string(s->mesh_id, "brain");
  s->vertex_count = nv;
  for (bool full : {true, false}) {
    s->encoding = full ? neurosim_ENCODING_FULL : neurosim_ENCODING_QUANTIZED_DELTA;
    s->displacement_m._length = 0;
    s->delta_q._length = 0;
    if (full)
      ns::assign(s->displacement_m, std::vector<float>(3 * nv, 1e-3f));
    else
      ns::assign(s->delta_q, std::vector<short>(3 * nv, 7));
    l.writer.write(*s);
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    ddsi_serdata* sd[1] = {nullptr};
    dds_sample_info_t info[1];
    const dds_return_t n = dds_takecdr(l.reader.handle(), sd, 1, info, DDS_ANY_STATE);
    ASSERT_EQ(n, 1);
    const std::uint32_t bytes = ddsi_serdata_size(sd[0]);
    ddsi_serdata_unref(sd[0]);
    // Payload alone: 4 B (float) or 2 B (int16) per component.
    const std::size_t payload = 3 * nv * (full ? 4 : 2);
    EXPECT_GE(bytes, payload);
    EXPECT_LT(bytes, payload + 256);
    std::printf("Deformation %s, %zu vertices: %u bytes serialized\n",
                full ? "FULL" : "QUANTIZED_DELTA", nv, bytes);
  }
}
