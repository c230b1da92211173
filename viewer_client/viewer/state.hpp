// What the viewer knows about the simulation: mesh topologies, their newest decoded
// displacements, the tools (pose from ToolState, force from ContactModel), the server's
// liveliness and its newest SimStatus (elasticity tier and its update rate). Fed from DDS
// samples (dds_client.hpp) or directly (tests, benchmark); no VTK here.
//
// Bad samples never throw out of ingest_*(): they are counted, the first few are reported through
// the warning callback, and the previous state is kept.
#pragma once

#include "idl/wire/deformation_codec.hpp"
#include "idl/wire/types.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <array>
#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <vector>

namespace neurosim::viewer {

struct MeshState {
  std::string id;
  std::uint32_t revision = 0;
  std::vector<Eigen::Vector3d> rest_m;      // rest vertices, unit m
  std::vector<std::array<int, 4>> tets;     // 0-based vertex ids
  std::vector<std::array<int, 3>> surface;  // outward triangles, 0-based vertex ids
  int priority = 0;
  // A rigid obstacle (the skull): surface only, no tets, never deformed (u_m stays zero).
  bool rigid = false;
  // Region (scene tissue) index of each tet into region_names; both empty when unlabelled.
  std::vector<std::uint8_t> tet_region;
  std::vector<std::string> region_names;
  std::string image_file;     // NIfTI the mesh maps to ("" none)
  double image_unit_m = 1.0;  // image physical units to m
  std::vector<float> u_m;     // 3 per vertex, unit m (zeros until a frame)
  std::uint64_t frame = 0;    // Deformation frame of u_m
  std::uint64_t server_step = 0;  // the server step u_m belongs to (Deformation.server_step)
  bool has_deformation = false;
  std::uint64_t u_version = 0;       // bumped whenever u_m changes
  float max_displacement_m = 0;      // max |u| of u_m, unit m
  wire::DeformationDecoder decoder;  // per topology (reset with it)
};

struct ToolView {
  std::string station;
  Eigen::Vector3d tip_m = Eigen::Vector3d::Zero();    // tool tip, scene frame, unit m
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();    // unit, from the tip towards the handle
  Eigen::Vector3d force_n = Eigen::Vector3d::Zero();  // newest ContactModel f0, unit N
  bool in_contact = false;
  bool has_pose = false;
};

// The part of the newest SimStatus the viewer shows.
struct ServerStatusView {
  bool received = false;            // a valid SimStatus arrived (from this or an earlier server)
  std::string server_id;
  std::string scene_name;
  std::string tier;                 // "LINEAR", "COROTATIONAL", "NONLINEAR" (the tier that runs)
  double tier_update_rate_hz = 0;   // equilibrium updates per second, 0 for LINEAR, unit Hz
  double step_rate_measured_hz = 0; // unit Hz
  double max_strain = -1;            // largest strain in the fields (0.14 = 14 %); -1: not measured
  double expected_force_error = -1;  // the tier's expected force error there (fraction); -1: unknown
  // Against the converged answer (nested refinements extrapolated): the host's mesh + element part
  // and the total (that + the tier's), fractions; -1: unknown.
  double discretization_error_estimate = -1;
  double total_error_estimate = -1;
};

// The expected tool-force error against the converged answer (nested refinements extrapolated)
// and its two parts, as the overlay shows it: "error vs converged answer ~17 % (mesh + element
// ~8 %, tier ~9 %)"; a part the server does not know says "unknown" (no table row for the
// element and mesh that run), the tier's "not measured" before a strain is, and the total is
// then "unknown". "" before the first SimStatus.
std::string error_text(const ServerStatusView& st);

struct ViewerCounters {
  std::uint64_t topologies = 0;            // accepted MeshTopology samples
  std::uint64_t deformations = 0;          // decoded Deformation frames
  std::uint64_t deformations_waiting = 0;  // deltas before their FULL frame, or no topology yet
  std::uint64_t tool_states = 0;
  std::uint64_t contact_models = 0;
  std::uint64_t malformed_topology = 0;
  std::uint64_t malformed_deformation = 0;
  std::uint64_t malformed_tool = 0;
  std::uint64_t malformed_contact = 0;
  std::uint64_t malformed_status = 0;  // unknown tier, negative or non-finite rates
  std::uint64_t statuses = 0;          // accepted SimStatus samples
  std::uint64_t server_seen = 0;  // SimStatus writer appeared (first time or after a loss)
  std::uint64_t server_lost = 0;  // SimStatus writer went away
  std::uint64_t malformed() const {
    return malformed_topology + malformed_deformation + malformed_tool + malformed_contact +
           malformed_status;
  }
};

// Colour of a tool carrying force |F| (paper's rule, f = |F| / force_unit_n with F in N):
// (R, G, B) = (min(0.2 + f, 1), max(0.2 - f, 0), max(0.2 - f, 0)): common::force_colour.
std::array<double, 3> force_colour(double force_n, double force_unit_n = 1.0);

// Shaft axis of a tool with orientation q (w, x, y, z): the tool frame's +z in the scene frame
// (the server's convention, server/service/server.cpp).
Eigen::Vector3d shaft_axis(double w, double x, double y, double z);

class ViewerState {
 public:
  using Warn = std::function<void(const std::string&)>;
  explicit ViewerState(Warn warn = {}, int max_warnings_per_kind = 5);

  // DDS samples. Return whether the state changed.
  bool ingest_topology(const neurosim_MeshTopology& t);
  bool ingest_deformation(const neurosim_Deformation& d);
  bool ingest_tool(const neurosim_ToolState& s);
  bool ingest_contact(const neurosim_ContactModel& c);
  bool ingest_status(const neurosim_SimStatus& s);
  void remove_station(const std::string& station);  // its writer left (disposed, no writers)
  void set_server_alive(bool alive);

  // Direct setters (benchmark, tests): throw std::invalid_argument on bad input.
  void set_mesh(MeshState mesh);
  void set_displacements(const std::string& mesh_id, std::vector<float> u_m);
  void set_tool(const ToolView& tool);

  const std::vector<MeshState>& meshes() const { return meshes_; }
  const MeshState* mesh(const std::string& id) const;
  const std::map<std::string, ToolView>& tools() const { return tools_; }
  // The tool the slices follow: the first station (by id) with a pose, or null.
  const ToolView* primary_tool() const;
  // Bumped whenever a mesh is added or replaced (renderer and resampler rebuild then).
  std::uint64_t topology_generation() const { return topology_generation_; }
  bool server_alive() const { return server_alive_; }
  bool server_ever_seen() const { return server_ever_seen_; }
  // The newest valid SimStatus (kept when the server goes away; a new server's replaces it).
  const ServerStatusView& server_status() const { return server_status_; }
  const ViewerCounters& counters() const { return counters_; }
  // Largest |u| over all meshes, unit m.
  double max_displacement_m() const;
  // Axis-aligned bounds of all rest vertices (min, max), unit m; zero if no mesh.
  std::pair<Eigen::Vector3d, Eigen::Vector3d> bounds_m() const;
  // The image file the meshes name (the first non-empty), and its unit.
  std::string image_file() const;
  double image_unit_m() const;

 private:
  void warn(int kind, const std::string& message);
  MeshState* find(const std::string& id);
  Warn warn_;
  int max_warnings_;
  std::array<int, 5> warned_{};
  std::vector<MeshState> meshes_;
  std::map<std::string, ToolView> tools_;
  std::uint64_t topology_generation_ = 0;
  bool server_alive_ = false;
  bool server_ever_seen_ = false;
  ServerStatusView server_status_;
  ViewerCounters counters_;
  std::vector<float> scratch_;
};

// Region index of each surface triangle of m: the region of the tetrahedron the triangle is a
// face of; -1 when m has no regions or no tetrahedron has that face.
std::vector<int> surface_regions(const MeshState& m);

// The MeshState a MeshTopology sample describes. Throws std::invalid_argument naming the mesh and
// the bad field, vertex or element.
MeshState mesh_from_topology(const neurosim_MeshTopology& t);

}  // namespace neurosim::viewer
