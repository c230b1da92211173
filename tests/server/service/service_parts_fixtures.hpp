// Test doubles for the service's parts without DDS traffic: a directory of ToolState writers
// (what discovery would say), ToolState samples as the reader hands them over, a recording
// ContactModel sink and a small Simulation whose step throws for a "poisoned" tip.
#pragma once

#include "server/interaction/simulation.hpp"
#include "server/mesh/tet_mesh.hpp"
#include "server/service/station_admission.hpp"
#include "server/service/step_loop.hpp"

#include <array>
#include <cstring>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

namespace neurosim::service::testing {

inline Guid guid_of(int n) {
  Guid g{};
  g[0] = static_cast<std::uint8_t>(n & 0xff);
  g[1] = static_cast<std::uint8_t>((n >> 8) & 0xff);
  g[15] = 0x5a;
  return g;
}

// Writers as discovery sees them: handle → (station claimed, participant).
class FakeDirectory : public WriterDirectory {
 public:
  void add(dds_instance_handle_t writer, const std::string& station, int participant) {
    wire::MatchedPublication mp;
    mp.matched = true;
    mp.guid = guid_of(static_cast<int>(writer));
    mp.participant_guid = guid_of(1000 + participant);
    mp.partitions = {std::string(wire::kStationPartitionPrefix) + station};
    writers_[writer] = mp;
  }
  void remove(dds_instance_handle_t writer) { writers_.erase(writer); }
  wire::MatchedPublication matched(dds_instance_handle_t writer) const override {
    const auto it = writers_.find(writer);
    return it == writers_.end() ? wire::MatchedPublication{} : it->second;
  }

 private:
  std::map<dds_instance_handle_t, wire::MatchedPublication> writers_;
};

// One ToolState sample of `station` from `writer`, as the reader would hand it over.
struct SampleIn {
  neurosim_ToolState data{};
  dds_sample_info_t info{};
  SampleIn(dds_instance_handle_t writer, const std::string& station, std::uint64_t sequence,
           double x_m = 0.0, std::int64_t source_time_ns = 0) {
    std::strncpy(data.station_id, station.c_str(), neurosim_ID_MAX);
    data.sequence_number = sequence;
    data.source_time_ns = source_time_ns;
    data.position_m[0] = x_m;
    data.orientation[0] = 1.0;
    info.valid_data = true;
    info.publication_handle = writer;
    info.instance_state = DDS_IST_ALIVE;
    info.sample_state = DDS_SST_NOT_READ;
    info.view_state = DDS_VST_NEW;
  }
  wire::Received<neurosim_ToolState> rx() const { return {data, info}; }
};

// ContactModel samples as written (copies of the fixed-size fields the tests read).
struct ModelOut {
  std::string station_id;
  std::uint64_t tool_sequence{0};
  bool in_contact{false};
  bool rejected{false};
  double f0_x_n{0.0};
  std::vector<std::array<double, 2>> relaxing;  // per relaxing part: (force x, unit N; tau_s)
};
class RecordingSink : public ContactModelSink {
 public:
  void write(const neurosim_ContactModel& m) override {
    written.push_back({m.station_id, m.tool_sequence, m.in_contact, m.tool_sample_rejected, m.f0_n[0], {}});
    for (std::uint32_t j = 0; j < m.relaxing_forces._length; ++j)
      written.back().relaxing.push_back({m.relaxing_forces._buffer[j].force_n[0], m.relaxing_forces._buffer[j].tau_s});
  }
  void dispose(const neurosim_ContactModel& k) override { disposed.emplace_back(k.station_id); }
  std::vector<ModelOut> written;
  std::vector<std::string> disposed;
};

// One tetrahedron; every tool below x = 0 is in contact with force (-k x, 0, 0), of which 40 %
// relaxes with 0.5 s and 20 % with 50 s when held (viscoelastic answers). A step with any
// tip at x >= kPoisonX throws (as a step meeting a pose it cannot solve), so the stations whose
// pose is poisoned can be told from the others.
class PoisonSimulation : public interaction::Simulation {
 public:
  static constexpr double kStiffness = 1000.0;  // N/m
  static constexpr double kPoisonX = 1.0;       // m
  PoisonSimulation()
      : mesh_(mesh::TetMesh::build({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}}, {{0, 1, 2, 3}})) {}
  int num_meshes() const override { return 1; }
  const std::string& mesh_id(int) const override { return id_; }
  const mesh::TetMesh& mesh(int) const override { return mesh_; }
  void step(const std::vector<interaction::ToolPose>& poses, std::vector<interaction::ToolContact>& contacts,
            interaction::StepStats&) override {
    ++calls;
    for (const auto& p : poses)
      if (p.tip_m.x() >= kPoisonX) throw std::runtime_error("tip beyond the poison plane");
    contacts.resize(poses.size());
    for (std::size_t k = 0; k < poses.size(); ++k) {
      auto& c = contacts[k];
      const double x = poses[k].tip_m.x();
      c.in_contact = x < 0.0;
      c.force_n = interaction::Vec3(c.in_contact ? -kStiffness * x : 0.0, 0, 0);
      c.num_relaxing = c.in_contact ? 2 : 0;
      c.relaxing[0] = {0.4 * c.force_n, 0.5};
      c.relaxing[1] = {0.2 * c.force_n, 50.0};
      c.reference_tip_m = poses[k].tip_m;
      c.mesh = c.in_contact ? 0 : -1;
    }
  }
  void displacements(int, Eigen::VectorXd& u) const override { u.setZero(12); }
  // The column worker's counts as the Simulation reports them (set by a test).
  std::uint64_t columns_not_ready() const override { return not_ready; }
  std::uint64_t columns_solved_ahead() const override { return solved_ahead; }
  std::uint64_t steps_with_rows_dropped() const override { return rows_dropped; }
  std::uint64_t steps_not_converged() const override { return not_converged; }
  std::uint64_t not_ready{0}, solved_ahead{0}, rows_dropped{0}, not_converged{0};
  // The column cache as the Simulation reports it (set by a test); the one mesh is body 0.
  int body_index(int) const override { return 0; }
  ColumnCacheStats column_cache(int) const override { return cache; }
  ColumnCacheStats cache{};
  bool mesh_active(int) const override { return true; }
  double tie_residual_m() const override { return 0.0; }
  const interaction::SetupStats& setup_stats() const override { return setup_; }
  const std::vector<int>& fixed_nodes(int) const override { return none_; }
  int num_tools() const override { return 1; }
  const interaction::CoupledBody* body_of(int) const override { return nullptr; }
  void last_contact_forces(int, std::vector<int>& s, std::vector<interaction::Vec3>& f) const override {
    s.clear();
    f.clear();
  }
  int calls{0};

 private:
  std::string id_{"block"};
  mesh::TetMesh mesh_;
  interaction::SetupStats setup_{};
  std::vector<int> none_;
};

}  // namespace neurosim::service::testing
