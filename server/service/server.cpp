#include "server/service/server.hpp"

#include "common/clock.hpp"
#include "common/stats.hpp"
#include "idl/wire/deformation_codec.hpp"
#include "idl/wire/dds.hpp"
#include "server/fem/strain.hpp"
#include "server/interaction/rigid_obstacle.hpp"
#include "server/interaction/tool_proxy.hpp"
#include "server/service/accuracy_table.hpp"
#include "server/service/log_limiter.hpp"
#include "server/service/pose_handoff.hpp"
#include "server/service/station_identity.hpp"
#include "server/service/tool_filter.hpp"

#include <pthread.h>
#include <sched.h>
#include <semaphore.h>
#include <time.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <map>
#include <mutex>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <thread>
#include <type_traits>
#include <unordered_map>

namespace neurosim::service {

namespace wire = neurosim::wire;
using interaction::ToolContact;
using interaction::ToolPose;

namespace {

constexpr int kMaxStationsLimit = 64;  // SimStatus.stations is sequence<StationStatus, 64>
const double kDefaultMaxSpeed = scene::ToolDef{}.max_speed_m_per_s;  // unit m/s

using common::monotonic_ns;

neurosim_Tier wire_tier(scene::Tier t) {
  switch (t) {
    case scene::Tier::kLinear: return neurosim_TIER_LINEAR;
    case scene::Tier::kCorotational: return neurosim_TIER_COROTATIONAL;
    case scene::Tier::kNonlinear: return neurosim_TIER_NONLINEAR;
  }
  throw std::invalid_argument("unknown elasticity tier");
}

std::string describe_setup(const interaction::Simulation& sim) {
  const auto& st = sim.setup_stats();
  std::ostringstream os;
  os << "physics built in " << st.total_s << " s: meshes " << st.load_meshes_s << " s, factor "
     << st.factor_s << " s, ";
  if (st.fusion_s == 0 && st.tied_nodes == 0)
    os << "inclusion decision: not run (no coupling)";
  else
    os << "inclusion decision + coupling map " << st.fusion_s << " s, condense " << st.condense_s
       << " s, boundary columns " << st.boundary_s << " s, coupling operator " << st.operator_s
       << " s (" << st.boundary_nodes << " boundary nodes, " << st.tied_nodes << " tied nodes)";
  os << ", contact columns " << st.columns_s << " s";
  return os.str();
}

enum SlotState : int { kFree = 0, kActive = 1, kLeaving = 2 };

// One station. The DDS thread owns join (Free → Active) and leave (Active → Leaving); the step
// thread retires (Leaving → Free). Poses cross through the triple buffer.
struct StationSlot {
  std::atomic<int> state{kFree};
  char station_id[neurosim_ID_MAX + 1]{};  // written by the DDS thread before state = Active
  common::TripleBuffer<PoseSample> pose;
  std::atomic<bool> last_rejected{false};
  std::atomic<std::uint64_t> accepted{0}, rejected_nonfinite{0}, rejected_jump{0}, last_sequence{0},
      rejected_workspace{0}, rejected_time{0}, rejected_sequence{0}, rejected_identity{0};
  std::atomic<bool> in_contact{false};  // written by the step thread
  // DDS thread only.
  ToolFilter filter;
  int tool{0};
  dds_instance_handle_t writer{0};  // the ToolState writer this station is bound to
  Guid participant{};               // that writer's participant
  std::int64_t last_sample_mono_ns{0};  // newest sample of the bound writer (any verdict)
  // Step thread only.
  bool step_joined{false};
  bool step_has_pose{false};
  bool model_written{false};
};

}  // namespace

struct Server::Impl {
  Impl(const scene::Model& model, std::unique_ptr<interaction::Simulation> s, ServerOptions o,
       std::ostream& l)
      : settings(model), sim(std::move(s)), opt(std::move(o)), log_stream(l) {
    for (const auto& m : model.meshes) {
      MeshInfo mi{m.id, m.material, m.priority, m.provenance, {}, {}};
      for (const auto& t : m.tissues) {
        mi.region_labels.push_back(t.label);
        mi.region_names.push_back(t.name);
      }
      mesh_info.push_back(std::move(mi));
    }
    rigid_surfaces = model.rigid;
    // Rigid obstacles (the skull): built only when the scene has them, else null and free.
    rigid = interaction::RigidObstacle::build(model.rigid);
    for (const auto& t : model.tools)
      tool_shapes.push_back({t.tip_radius_m, t.shaft_radius_m, t.shaft_length_m});
  }

  // ---- Model (built once) --------------------------------------------------------------------
  scene::Settings settings;
  struct MeshInfo {  // what MeshTopology says of each scene mesh
    std::string id;
    fem::Material material;
    int priority;
    std::string provenance;
    std::vector<int> region_labels;         // scene tissues' labels (tet_region indexes these)
    std::vector<std::string> region_names;  // and their names
  };
  std::vector<MeshInfo> mesh_info;
  std::vector<scene::RigidSurface> rigid_surfaces;  // published as rigid MeshTopology samples
  std::unique_ptr<interaction::Simulation> sim;
  std::unique_ptr<const interaction::RigidObstacle> rigid;  // null: the scene has none
  std::vector<interaction::ToolShape> tool_shapes;          // per scene tool
  ServerOptions opt;
  std::ostream& log_stream;
  std::mutex log_mutex;

  double step_hz{1000}, viewer_hz{30}, status_hz{1};
  std::int64_t period_ns{1000000};
  std::uint64_t viewer_every{33}, status_every{1000};
  int max_stations{8};
  bool tool_contact{true};
  bool deformation_output{false};
  std::string effects_text;
  std::vector<double> tool_max_speed;  // per scene tool, m/s
  std::vector<std::string> tool_ids;
  Workspace workspace;                 // scene bounding box + opt.workspace_margin_m

  // Declared before the participant: its topic filter points here, so it must outlive it.
  WriterClaims claims;
  std::optional<wire::Participant> pp;
  std::optional<wire::Topic<neurosim_ToolState>> tool_topic;
  std::optional<wire::Topic<neurosim_ContactModel>> model_topic;
  std::optional<wire::Topic<neurosim_Deformation>> deform_topic;
  std::optional<wire::Topic<neurosim_MeshTopology>> topo_topic;
  std::optional<wire::Topic<neurosim_SimStatus>> status_topic;
  std::optional<wire::Reader<neurosim_ToolState>> tools;
  std::optional<wire::Writer<neurosim_ContactModel>> models;
  std::optional<wire::Writer<neurosim_Deformation>> deformations;
  std::optional<wire::Writer<neurosim_MeshTopology>> topologies;
  std::optional<wire::Writer<neurosim_SimStatus>> status_writer;
  std::optional<wire::Waitset> waitset;

  // ---- State ---------------------------------------------------------------------------------
  std::vector<StationSlot> slots;
  std::vector<wire::Sample<neurosim_ContactModel>> models_out;  // one per slot
  std::vector<std::vector<ToolPose>> poses_by_count;            // [n] has n poses (no realloc)
  std::vector<std::vector<ToolContact>> contacts_by_count;
  std::vector<int> slot_of_pose;
  // With rigid obstacles only: per slot the server-side proxy and the step's planes.
  std::vector<interaction::ToolProxy> proxies;
  std::vector<interaction::ObstaclePlanes> rigid_planes;
  std::vector<wire::DeformationEncoder> encoders;
  std::vector<wire::Sample<neurosim_Deformation>> deform_out;
  std::vector<bool> deform_written;
  std::vector<Eigen::VectorXd> u_m;  // per mesh, 3N, unit m
  std::uint32_t last_matched_viewers{0};
  std::atomic<bool> full_frame_pending{false};  // a new viewer matched: next frames FULL
  // Field worker handshake: the step thread posts a job only when the worker is idle.
  std::atomic<bool> field_busy{false};
  interaction::FieldSnapshot field_snapshot;  // written by the step thread while the field thread is idle
  bool field_job_strain{false};   // measure the largest strain
  std::uint64_t field_job_step{0};
  std::int64_t field_job_time_ns{0};
  std::mutex field_mutex;
  std::condition_variable field_cv;
  bool field_job{false};
  std::thread field_thread;
  wire::Sample<neurosim_SimStatus> status;
  std::vector<neurosim_StationStatus> station_status;
  // Accuracy shown where the user works: the largest strain of the fields (field thread, once
  // per status period) and the tier's expected force error there (accuracy table).
  std::optional<AccuracyTable> accuracy;
  std::atomic<bool> strain_due{false};
  std::atomic<double> field_max_strain{-1.0};
  bool error_bound_warned{false};
  bool beyond_table_noted{false};
  std::uint64_t tier_failures_logged{0};
  std::vector<double> step_us, step_us_sorted;  // this status period
  std::size_t step_us_count{0};
  std::int64_t start_mono_ns{0};
  std::int64_t last_status_mono_ns{0};
  std::uint64_t steps_at_last_status{0};

  // DDS thread only.
  std::unordered_map<std::string, int> slot_of_station;
  std::optional<LogLimiter> log_limit;
  std::int64_t last_sweep_mono_ns{0};
  // Recent refusals (bounded), newest first; copied into SimStatus.refused by the step thread.
  static constexpr std::size_t kMaxRefusals = 16;
  static constexpr std::int64_t kRefusalMemoryNs = 5000000000;  // forgotten 5 s after the last sample
  std::mutex refusal_mutex;
  std::vector<neurosim_StationRefusal> refusals;
  std::atomic<bool> status_soon{false};  // a new refusal: publish SimStatus early
  std::atomic<std::uint64_t> suppressed_lines{0};  // log_limit's total, for the step thread

  std::atomic<bool> run{false};
  std::atomic<bool> started{false};
  std::atomic<bool> stopped{false};
  mutable std::mutex error_mutex;
  std::string error_text;
  std::atomic<std::uint64_t> steps{0}, deadline_misses{0}, rejected_nonfinite{0}, rejected_jump{0},
      stations_refused{0}, deformation_frames{0}, full_field_solves{0}, deformation_skipped{0},
      rejected_workspace{0}, rejected_time{0}, rejected_sequence{0}, rejected_identity_dds{0},
      rejected_rate{0}, stations_reclaimed{0}, unknown_ids_dropped{0};
  std::uint64_t rejected_identity() const { return rejected_identity_dds.load() + claims.filtered(); }
  std::thread dds_thread, step_thread;
  // Event step mode: the DDS thread posts after each pose it hands to a slot; the step thread
  // waits on it until its deadline (one semaphore: no lock on either side beyond it).
  sem_t step_wake;
  std::atomic<std::uint64_t> steps_on_sample{0}, steps_on_deadline{0};
  std::int64_t viewer_period_ns{33333333}, status_period_ns{1000000000};
  std::int64_t next_viewer_ns{0};
  bool wait_for_sample(std::int64_t deadline_ns);

  void log(const std::string& line) {
    std::lock_guard<std::mutex> lk(log_mutex);
    log_stream << "neurosim-server: " << line << '\n' << std::flush;
  }
  void fail(const std::string& where, const std::exception& e) {
    {
      std::lock_guard<std::mutex> lk(error_mutex);
      if (error_text.empty()) error_text = where + ": " + e.what();
    }
    log("error in " + where + ": " + e.what());
    run = false;
    if (waitset) {
      try {
        waitset->wake();
      } catch (...) {
      }
    }
  }

  void configure();
  void create_entities();
  void publish_topologies();
  static void set_regions(neurosim_MeshTopology& t, const std::vector<int>& labels,
                          std::size_t num_tets, const MeshInfo& info);
  void dds_loop();
  void handle_tool_sample(const wire::Received<neurosim_ToolState>& rx);
  void leave(const std::string& key, const char* why);
  void limited_log(const char* cause, const std::string& line);
  void refuse(const std::string& key, dds_instance_handle_t writer, neurosim_RefusalReason reason,
              const std::string& why);
  std::optional<WriterInfo> writer_info(dds_instance_handle_t writer);
  void sweep(std::int64_t now_mono);
  void step_loop();
  void one_step();
  void retire(int i);
  void publish_deformation(std::uint64_t step, std::int64_t now_ns);
  void encode_and_write(std::uint64_t step, std::int64_t now_ns, bool strain);
  void field_loop();
  void publish_status(std::int64_t now_mono);
  void report_accuracy(neurosim_SimStatus& st);
  void dispose_all();
};

// ---------------------------------------------------------------------------------------------
void Server::Impl::configure() {
  const auto& r = settings.rates;
  step_hz = r.step_hz;
  viewer_hz = r.viewer_hz;
  status_hz = r.status_hz;
  if (!(std::isfinite(step_hz) && std::isfinite(viewer_hz) && std::isfinite(status_hz)))
    throw std::runtime_error(opt.scene_path + ": rates: not finite");
  period_ns = static_cast<std::int64_t>(std::llround(1e9 / step_hz));
  if (period_ns < 1000) throw std::runtime_error(opt.scene_path + ": rates.step_hz: above 1 MHz");
  viewer_every = std::max<std::uint64_t>(1, std::llround(step_hz / viewer_hz));
  status_every = std::max<std::uint64_t>(1, std::llround(step_hz / status_hz));
  // Viewer frames and SimStatus on the clock (event step mode steps at a varying rate).
  viewer_period_ns = static_cast<std::int64_t>(viewer_every) * period_ns;
  status_period_ns = static_cast<std::int64_t>(status_every) * period_ns;
  if (!(opt.max_step_rate_factor >= 1.0 && opt.max_step_rate_factor <= 100.0))
    throw std::invalid_argument("max_step_rate_factor " + std::to_string(opt.max_step_rate_factor) +
                                " must be in [1, 100]");
  for (const char* role : {"step", "dds", "field"}) (void)opt.threads.at(role);  // all three named
  if (sem_init(&step_wake, 0, 0) != 0) throw std::runtime_error("sem_init failed");
  max_stations = settings.max_stations;
  if (max_stations > kMaxStationsLimit)
    throw std::runtime_error(opt.scene_path + ": max_stations: " + std::to_string(max_stations) +
                             " is above " + std::to_string(kMaxStationsLimit));
  const auto& fx = settings.effects;
  tool_contact = fx.tool_contact;
  deformation_output = fx.deformation_output;
  std::string e;
  auto add = [&](bool on, const char* name) {
    if (!on) return;
    if (!e.empty()) e += ',';
    e += name;
  };
  add(fx.tool_contact, "contact");
  add(fx.coupling, "coupling");
  add(fx.deformation_output, "deformation");
  effects_text = e;
  for (const auto& t : settings.tools) {
    tool_ids.push_back(t.id);
    tool_max_speed.push_back(t.max_speed_m_per_s);
  }
  if (sim == nullptr) throw std::runtime_error("Server: no simulation");
  if (!(std::isfinite(opt.station_idle_timeout_s) && opt.station_idle_timeout_s >= 0.05 &&
        opt.station_idle_timeout_s <= 3600))
    throw std::runtime_error("station idle timeout " + std::to_string(opt.station_idle_timeout_s) +
                             " s is outside [0.05, 3600] s");
  if (opt.max_stations_per_participant < 1)
    throw std::runtime_error("max stations per participant " +
                             std::to_string(opt.max_stations_per_participant) + " is below 1");
  if (!(std::isfinite(opt.workspace_margin_m) && opt.workspace_margin_m >= 0 && opt.workspace_margin_m <= 100))
    throw std::runtime_error("workspace margin " + std::to_string(opt.workspace_margin_m) +
                             " m is outside [0, 100] m");
  if (!(std::isfinite(opt.max_future_s) && opt.max_future_s >= 0))
    throw std::runtime_error("max future " + std::to_string(opt.max_future_s) + " s is not finite and >= 0");
  if (!(std::isfinite(opt.max_station_rate_hz) && opt.max_station_rate_hz >= 10))
    throw std::runtime_error("max station rate " + std::to_string(opt.max_station_rate_hz) +
                             " Hz is not finite and >= 10 Hz");
  log_limit.emplace(opt.log_lines_per_second);
  if (sim->num_meshes() != static_cast<int>(mesh_info.size()))
    throw std::runtime_error(opt.scene_path + ": the simulation has " +
                             std::to_string(sim->num_meshes()) + " meshes, the scene " +
                             std::to_string(mesh_info.size()));

  // Simulation::tier() promises the scene's tier and never another one; a simulation that runs
  // another would publish a SimStatus.tier the scene (and --tier) did not ask for: refuse it.
  if (sim->tier() != fx.tier)
    throw std::runtime_error(opt.scene_path + ": the simulation runs tier " +
                             scene::tier_name(sim->tier()) + ", not the tier asked for: " +
                             scene::tier_name(fx.tier) + " (from " + opt.tier_source + ")");

  if (!opt.accuracy_table.empty()) {
    accuracy = AccuracyTable::read(opt.accuracy_table);
    log("accuracy table " + opt.accuracy_table + ": " + std::to_string(accuracy->rows().size()) +
        " measured rows" +
        (deformation_output ? std::string()
                            : std::string(" (no strain measured: effects.deformation_output is "
                                          "off, so no expected error either)")) +
        "; the strain is measured in the fields solved for viewers, while one is matched");
  } else {
    log("no accuracy table: SimStatus.expected_force_error stays -1 (unknown)");
  }
  // Workspace: the bounding box of every mesh's rest vertices, enlarged by the margin.
  for (int i = 0; i < 3; ++i) {
    workspace.min_m[i] = std::numeric_limits<double>::max();
    workspace.max_m[i] = -std::numeric_limits<double>::max();
  }
  for (int m = 0; m < sim->num_meshes(); ++m)
    for (const auto& x : sim->mesh(m).vertices())
      for (int i = 0; i < 3; ++i) {
        workspace.min_m[i] = std::min(workspace.min_m[i], x[i]);
        workspace.max_m[i] = std::max(workspace.max_m[i], x[i]);
      }
  for (int i = 0; i < 3; ++i) {
    if (workspace.min_m[i] > workspace.max_m[i]) workspace.min_m[i] = workspace.max_m[i] = 0;  // no vertices
    workspace.min_m[i] -= opt.workspace_margin_m;
    workspace.max_m[i] += opt.workspace_margin_m;
  }
  {
    std::ostringstream w;
    w << "stations: workspace [" << workspace.min_m[0] << ", " << workspace.max_m[0] << "] x ["
      << workspace.min_m[1] << ", " << workspace.max_m[1] << "] x [" << workspace.min_m[2] << ", "
      << workspace.max_m[2] << "] m (scene bounding box + " << opt.workspace_margin_m
      << " m), idle timeout " << opt.station_idle_timeout_s << " s, at most "
      << opt.max_stations_per_participant << " per participant, at most " << opt.max_station_rate_hz
      << " samples/s each, source time at most " << opt.max_future_s << " s ahead";
    log(w.str());
  }
  const std::string setup = describe_setup(*sim);
  if (!setup.empty()) log(setup);
  std::ostringstream s;
  s << "scene '" << settings.name << "' (" << opt.scene_path << "): tier "
    << scene::tier_name(sim->tier()) << " (from " << opt.tier_source << "), effects ["
    << effects_text << "], step " << step_hz << " Hz, viewer " << viewer_hz << " Hz, status "
    << status_hz << " Hz, max " << max_stations << " stations";
  log(s.str());
}

void Server::Impl::create_entities() {
  wire::ParticipantOptions po;
  if (opt.domain >= 0) po.domain = static_cast<dds_domainid_t>(opt.domain);
  pp.emplace(po);
  const std::string& p = opt.topic_prefix;
  topo_topic.emplace(*pp, wire::topic_name<neurosim_MeshTopology>(p));
  topologies.emplace(*pp, *topo_topic);
  status_topic.emplace(*pp, wire::topic_name<neurosim_SimStatus>(p));
  status_writer.emplace(*pp, *status_topic);
  waitset.emplace(*pp);
  log("built: MeshTopology writer (" + std::to_string(sim->num_meshes()) +
      " meshes), SimStatus writer");

  if (tool_contact) {
    tool_topic.emplace(*pp, wire::topic_name<neurosim_ToolState>(p));
    // The identity filter before the reader exists (Cyclone: not thread-safe afterwards).
    claims.install_filter(tool_topic->handle());
    model_topic.emplace(*pp, wire::topic_name<neurosim_ContactModel>(p));
    tools.emplace(*pp, *tool_topic);
    models.emplace(*pp, *model_topic);
    waitset->attach_data(*tools, 1);
    waitset->attach_liveliness(*tools, 2);
    slots = std::vector<StationSlot>(static_cast<std::size_t>(max_stations));
    models_out.resize(slots.size());
    poses_by_count.resize(slots.size() + 1);
    contacts_by_count.resize(slots.size() + 1);
    for (std::size_t n = 0; n <= slots.size(); ++n) {
      poses_by_count[n].resize(n);
      contacts_by_count[n].resize(n);
    }
    slot_of_pose.resize(slots.size());
    if (rigid) {
      // The proxy's planes must cover the fastest tool's travel in one step.
      interaction::ToolProxyOptions proxy_options;
      for (double v : tool_max_speed) proxy_options.reach_m = std::max(proxy_options.reach_m, 1.5 * v / step_hz);
      proxy_options.max_reach_m = std::max(proxy_options.max_reach_m, proxy_options.reach_m);
      for (std::size_t i = 0; i < slots.size(); ++i) {
        proxies.emplace_back(*rigid, proxy_options);
        wire::reserve(models_out[i]->rigid_planes, interaction::kMaxObstaclePlanes);
      }
      rigid_planes.resize(slots.size());
      log("built: rigid obstacles (" + std::to_string(rigid->num_triangles()) +
          " triangles), a tool proxy per station slot (reach " + std::to_string(1e3 * proxy_options.reach_m) + " mm)");
    }
    log("built: ToolState reader (partition " + std::string(wire::kToolStateReaderPartition) +
        ", station identity filter), ContactModel writer, " + std::to_string(max_stations) +
        " station slots");
  } else {
    log("not built: stations (effects.tool_contact off): no ToolState reader, no ContactModel");
  }

  if (deformation_output) {
    deform_topic.emplace(*pp, wire::topic_name<neurosim_Deformation>(p));
    deformations.emplace(*pp, *deform_topic);
    wire::DeformationEncoderOptions eo;
    eo.full_frame_period = opt.full_frame_period;
    for (int m = 0; m < sim->num_meshes(); ++m) {
      encoders.emplace_back(sim->mesh_id(m), sim->mesh(m).num_vertices(), 1, eo);
      deform_out.emplace_back();
      u_m.emplace_back(Eigen::VectorXd::Zero(3 * static_cast<Eigen::Index>(sim->mesh(m).num_vertices())));
    }
    deform_written.assign(static_cast<std::size_t>(sim->num_meshes()), false);
    log("built: Deformation writer, " + std::to_string(sim->num_meshes()) + " encoders (" +
        std::to_string(viewer_hz) + " Hz, FULL frame every " + std::to_string(opt.full_frame_period) +
        " frames); full-field solves only while a viewer is matched, " +
        "on the field thread from a snapshot of each step's forces");
  } else {
    log("not built: Deformation (effects.deformation_output off): no full-field solves");
  }

  // Status: strings and buffers set once.
  wire::set_string(status->server_id, opt.server_id, "server_id");
  wire::set_string(status->scene_name, settings.name);
  wire::set_string(status->effects, effects_text);
  status->step_rate_target_hz = step_hz;
  status->viewer_rate_hz = deformation_output ? viewer_hz : 0.0;
  status->status_rate_hz = status_hz;
  status->max_stations = static_cast<std::uint32_t>(max_stations);
  station_status.resize(slots.size());
  wire::reserve(status->stations, slots.size());
  wire::reserve(status->refused, kMaxRefusals);
  refusals.reserve(kMaxRefusals + 1);
  const std::size_t per_period =
      static_cast<std::size_t>(static_cast<double>(status_every) * (opt.max_step_rate_factor + 1.0)) + 64;
  step_us.assign(per_period, 0.0);
  step_us_sorted.assign(per_period, 0.0);
}

void Server::Impl::publish_topologies() {
  for (int m = 0; m < sim->num_meshes(); ++m) {
    const auto& mesh = sim->mesh(m);
    const auto& id = sim->mesh_id(m);
    const MeshInfo* info = nullptr;
    for (const auto& mi : mesh_info)
      if (mi.id == id) info = &mi;
    wire::Sample<neurosim_MeshTopology> t;
    wire::set_string(t->mesh_id, id, "mesh_id");
    t->revision = 1;
    wire::set_string(t->scene_name, settings.name);
    std::vector<double> v;
    v.reserve(3 * mesh.num_vertices());
    for (const auto& x : mesh.vertices()) v.insert(v.end(), {x.x(), x.y(), x.z()});
    wire::assign(t->rest_vertices_m, v);
    std::vector<std::int32_t> tets;
    tets.reserve(4 * mesh.num_tets());
    for (const auto& te : mesh.tets()) tets.insert(tets.end(), te.begin(), te.end());
    wire::assign(t->tetrahedra, tets);
    std::vector<std::int32_t> tris;
    tris.reserve(3 * mesh.surface().size());
    for (const auto& tr : mesh.surface()) tris.insert(tris.end(), tr.begin(), tr.end());
    wire::assign(t->surface_triangles, tris);
    if (info != nullptr) {
      wire::set_string(t->material_name, info->material.name);
      t->youngs_modulus_pa = info->material.youngs_modulus_pa;
      t->poisson_ratio = info->material.poisson_ratio;
      t->priority = info->priority;
      wire::set_string(t->provenance, info->provenance);
      set_regions(*t, mesh.tet_labels(), mesh.num_tets(), *info);
    } else {
      wire::set_string(t->material_name, "");
      wire::set_string(t->provenance, "");
    }
    wire::set_string(t->volume_image_file, settings.image.file);
    t->volume_image_unit_m = settings.image.file_unit_m;
    topologies->write(*t);
    log("published MeshTopology '" + id + "': " + std::to_string(mesh.num_vertices()) +
        " vertices, " + std::to_string(mesh.num_tets()) + " tetrahedra, " +
        std::to_string(mesh.surface().size()) + " surface triangles");
  }
  // Rigid obstacles (the skull): surface only, never deformed (no Deformation frames).
  for (const scene::RigidSurface& r : rigid_surfaces) {
    wire::Sample<neurosim_MeshTopology> t;
    wire::set_string(t->mesh_id, r.id, "mesh_id");
    t->revision = 1;
    t->rigid = true;
    wire::set_string(t->scene_name, settings.name);
    std::vector<double> v;
    v.reserve(3 * r.vertices_m.size());
    for (const auto& x : r.vertices_m) v.insert(v.end(), {x.x(), x.y(), x.z()});
    wire::assign(t->rest_vertices_m, v);
    std::vector<std::int32_t> tris;
    tris.reserve(3 * r.triangles.size());
    for (const auto& tr : r.triangles) tris.insert(tris.end(), tr.begin(), tr.end());
    wire::assign(t->surface_triangles, tris);
    wire::set_string(t->material_name, "");
    wire::set_string(t->provenance, r.provenance);
    wire::set_string(t->volume_image_file, settings.image.file);
    t->volume_image_unit_m = settings.image.file_unit_m;
    topologies->write(*t);
    log("published MeshTopology '" + r.id + "' (rigid): " + std::to_string(r.vertices_m.size()) +
        " vertices, " + std::to_string(r.triangles.size()) + " surface triangles");
  }
}

// tet_region / region_names of a labelled mesh: each tetrahedron's label as the index of its
// scene tissue. Left empty when the scene names no tissues or the solved mesh's tetrahedra are
// not the labelled ones (a mesh rebuilt by the simulation).
void Server::Impl::set_regions(neurosim_MeshTopology& t, const std::vector<int>& labels,
                               std::size_t num_tets, const MeshInfo& info) {
  if (info.region_names.empty() || labels.size() != num_tets) return;
  if (info.region_names.size() > 16)
    throw std::invalid_argument("mesh '" + info.id + "': " +
                                std::to_string(info.region_names.size()) +
                                " tissues, MeshTopology carries at most 16 region names");
  std::vector<std::uint8_t> region(num_tets);
  for (std::size_t e = 0; e < num_tets; ++e) {
    const auto it = std::find(info.region_labels.begin(), info.region_labels.end(), labels[e]);
    if (it == info.region_labels.end())
      throw std::invalid_argument("mesh '" + info.id + "': tetrahedron " + std::to_string(e) +
                                  " has label " + std::to_string(labels[e]) +
                                  ", which no tissue lists");
    region[e] = static_cast<std::uint8_t>(it - info.region_labels.begin());
  }
  wire::assign(t.tet_region, region);
  wire::reserve(t.region_names, info.region_names.size());
  for (std::size_t i = 0; i < info.region_names.size(); ++i)
    wire::set_string(t.region_names._buffer[i], info.region_names[i], "region name");
  t.region_names._length = static_cast<std::uint32_t>(info.region_names.size());
}

// ---------------------------------------------------------------------------------------------
// DDS thread.
void Server::Impl::dds_loop() {
  try {
    log(common::apply_to_this_thread(opt.threads.at("dds")));
    const std::size_t max_take = 64;  // wire::ReaderOptions default
    while (run.load()) {
      const auto r = waitset->wait(DDS_MSECS(100));
      if (!run.load()) break;
      if (!tools) continue;
      for (;;) {
        const auto batch = tools->take();
        for (const auto& rx : batch) handle_tool_sample(rx);
        if (batch.size() < max_take) break;
      }
      if (r.has(2)) {
        const auto l = tools->liveliness();
        if (l.not_alive_count_change > 0) {
          limited_log("liveliness", "ToolState writers lost liveliness: " +
                                        std::to_string(l.not_alive_count_change) + " (alive now " +
                                        std::to_string(l.alive_count) + ")");
          // The writer of the newest change: release its station at once (others: sweep).
          for (auto it = slot_of_station.begin(); it != slot_of_station.end(); ++it)
            if (slots[static_cast<std::size_t>(it->second)].writer == l.last_publication_handle) {
              const std::string key = it->first;
              leave(key, "its writer lost liveliness");
              break;
            }
        }
      }
      const std::int64_t now = monotonic_ns();
      if (now - last_sweep_mono_ns >= 100000000) sweep(now);
    }
  } catch (const std::exception& e) {
    fail("DDS thread", e);
  }
}

void Server::Impl::limited_log(const char* cause, const std::string& line) {
  std::string summary;
  const bool ok = log_limit->allow(cause, monotonic_ns(), &summary);
  suppressed_lines.store(log_limit->suppressed_total(), std::memory_order_relaxed);
  if (!summary.empty()) log(summary);
  if (ok) log(line);
}

void Server::Impl::leave(const std::string& key, const char* why) {
  const auto it = slot_of_station.find(key);
  if (it == slot_of_station.end()) return;
  auto& s = slots[static_cast<std::size_t>(it->second)];
  s.writer = 0;
  s.state.store(kLeaving, std::memory_order_release);
  limited_log("leave", "station '" + key + "' left (" + why + "), slot " + std::to_string(it->second));
  slot_of_station.erase(it);
}

// Every 100 ms: stations idle longer than the timeout or whose writer is gone free their slot;
// cached writers that are no longer matched and old refusals are forgotten.
void Server::Impl::sweep(std::int64_t now) {
  last_sweep_mono_ns = now;
  const auto idle_ns = static_cast<std::int64_t>(opt.station_idle_timeout_s * 1e9);
  std::vector<std::pair<std::string, const char*>> gone;
  for (const auto& [key, i] : slot_of_station) {
    const auto& s = slots[static_cast<std::size_t>(i)];
    if (now - s.last_sample_mono_ns > idle_ns) {
      gone.emplace_back(key, "idle: no sample within the station idle timeout, slot reclaimed");
    } else if (!tools->matched_publication(s.writer).matched) {
      gone.emplace_back(key, "its writer is gone");
    }
  }
  for (const auto& [key, why] : gone) {
    if (why[0] == 'i') ++stations_reclaimed;
    leave(key, why);
  }
  for (const auto h : claims.writers())
    if (!tools->matched_publication(h).matched) claims.erase(h);
  const std::int64_t wall = dds_time();
  std::lock_guard<std::mutex> lk(refusal_mutex);
  refusals.erase(std::remove_if(refusals.begin(), refusals.end(),
                                [&](const neurosim_StationRefusal& r) { return wall - r.time_ns > kRefusalMemoryNs; }),
                 refusals.end());
}

// The writer's claim from the cache, else from discovery (then cached). nullopt: not matched
// (gone already) or the cache is full of live writers.
std::optional<WriterInfo> Server::Impl::writer_info(dds_instance_handle_t writer) {
  if (auto w = claims.find(writer)) return w;
  const wire::MatchedPublication mp = tools->matched_publication(writer);
  if (!mp.matched) return std::nullopt;
  WriterInfo info;
  info.claim = station_claim(mp.partitions).value_or(std::string());
  info.guid = mp.guid;
  info.participant = mp.participant_guid;
  if (!claims.insert(writer, info)) {
    for (const auto h : claims.writers())
      if (!tools->matched_publication(h).matched) claims.erase(h);
    if (!claims.insert(writer, info)) return std::nullopt;
  }
  return info;
}

void Server::Impl::refuse(const std::string& key, dds_instance_handle_t writer,
                          neurosim_RefusalReason reason, const std::string& why) {
  Guid guid{};
  if (auto w = claims.find(writer)) guid = w->guid;
  const std::int64_t wall = dds_time();
  bool fresh = true;
  {
    std::lock_guard<std::mutex> lk(refusal_mutex);
    auto it = std::find_if(refusals.begin(), refusals.end(), [&](const neurosim_StationRefusal& r) {
      return std::memcmp(r.writer_guid, guid.data(), 16) == 0 && key == r.station_id && r.reason == reason;
    });
    if (it != refusals.end()) {
      it->time_ns = wall;
      fresh = false;
    } else {
      neurosim_StationRefusal r{};
      std::strncpy(r.station_id, key.c_str(), neurosim_ID_MAX);
      std::memcpy(r.writer_guid, guid.data(), 16);
      r.reason = reason;
      r.time_ns = wall;
      refusals.insert(refusals.begin(), r);
      if (refusals.size() > kMaxRefusals) {
        refusals.pop_back();
        ++unknown_ids_dropped;
      }
    }
  }
  if (!fresh) return;
  if (reason != neurosim_REFUSED_IDENTITY) ++stations_refused;
  status_soon.store(true, std::memory_order_release);
  limited_log("refused", "refused station '" + key + "': " + why);
}

void Server::Impl::handle_tool_sample(const wire::Received<neurosim_ToolState>& rx) {
  const ReceiveTime at{monotonic_ns(), dds_time()};
  const std::string key(rx.key());
  const dds_instance_handle_t writer = rx.info.publication_handle;
  const auto bound = slot_of_station.find(key);
  if (!rx.valid()) {
    // Only the bound writer may end its station (a dispose by another writer is ignored).
    if (bound == slot_of_station.end()) return;
    if (rx.no_writers()) leave(key, "no writers / liveliness lost");
    else if (rx.disposed() && slots[static_cast<std::size_t>(bound->second)].writer == writer)
      leave(key, "disposed");
    return;
  }
  auto identity_reject = [&](const std::string& why, bool refusal) {
    ++rejected_identity_dds;
    if (bound != slot_of_station.end())
      slots[static_cast<std::size_t>(bound->second)].rejected_identity.fetch_add(1, std::memory_order_relaxed);
    if (refusal) refuse(key, writer, neurosim_REFUSED_IDENTITY, why);
    else limited_log("identity", "rejected ToolState for '" + key + "': " + why);
  };
  const std::optional<WriterInfo> w = writer_info(writer);
  if (!w) return identity_reject("writer not matched (gone) or too many writers", false);
  if (key.empty() || w->claim != key)
    return identity_reject("the writer's partition claims '" + w->claim + "', not '" + key +
                               "' (a ToolState writer publishes in partition " +
                               wire::kStationPartitionPrefix + "<its station_id>)",
                           true);
  auto it = bound;
  if (it != slot_of_station.end() && slots[static_cast<std::size_t>(it->second)].writer != writer)
    return identity_reject("station id bound to another writer (until that writer is gone or idle " +
                               std::to_string(opt.station_idle_timeout_s) + " s)",
                           true);
  if (it == slot_of_station.end()) {
    int same_participant = 0;
    for (const auto& [k, i] : slot_of_station)
      if (slots[static_cast<std::size_t>(i)].participant == w->participant) ++same_participant;
    if (same_participant >= opt.max_stations_per_participant)
      return refuse(key, writer, neurosim_REFUSED_PARTICIPANT_LIMIT,
                    "its DDS participant already holds " + std::to_string(same_participant) +
                        " stations (max " + std::to_string(opt.max_stations_per_participant) +
                        " per participant)");
    int free_slot = -1;
    for (std::size_t i = 0; i < slots.size(); ++i)
      if (slots[i].state.load(std::memory_order_acquire) == kFree) {
        free_slot = static_cast<int>(i);
        break;
      }
    if (free_slot < 0)
      return refuse(key, writer, neurosim_REFUSED_MAX_STATIONS,
                    "max_stations " + std::to_string(max_stations) + " reached (" +
                        std::to_string(slot_of_station.size()) + " active, some may be leaving)");
    auto& s = slots[static_cast<std::size_t>(free_slot)];
    std::memcpy(s.station_id, rx.data.station_id, sizeof(s.station_id));
    const std::string tool(rx.data.tool_id);
    double vmax = kDefaultMaxSpeed;
    std::string tool_note;
    const auto ti = std::find(tool_ids.begin(), tool_ids.end(), tool);
    if (ti != tool_ids.end()) {
      vmax = tool_max_speed[static_cast<std::size_t>(ti - tool_ids.begin())];
    } else if (!tool_ids.empty()) {
      vmax = tool_max_speed[0];
      tool_note = " (unknown tool '" + tool + "': using '" + tool_ids[0] + "')";
    }
    ToolFilterDef fd;
    fd.max_speed_m_per_s = vmax;
    fd.workspace = workspace;
    fd.max_future_s = opt.max_future_s;
    fd.max_rate_hz = opt.max_station_rate_hz;
    s.filter = ToolFilter(fd);
    s.tool = ti != tool_ids.end() ? static_cast<int>(ti - tool_ids.begin()) : 0;
    s.writer = writer;
    s.participant = w->participant;
    s.last_sample_mono_ns = at.monotonic_ns;
    s.accepted = 0;
    s.rejected_nonfinite = 0;
    s.rejected_jump = 0;
    s.rejected_workspace = 0;
    s.rejected_time = 0;
    s.rejected_sequence = 0;
    s.rejected_identity = 0;
    s.last_sequence = 0;
    s.last_rejected = false;
    s.state.store(kActive, std::memory_order_release);
    it = slot_of_station.emplace(key, free_slot).first;
    std::ostringstream os;
    os << "station '" << key << "' joined, slot " << free_slot << ", tool '" << tool
       << "', max speed " << vmax << " m/s" << tool_note;
    limited_log("join", os.str());
  }
  auto& s = slots[static_cast<std::size_t>(it->second)];
  s.last_sample_mono_ns = at.monotonic_ns;
  double q[4];
  const Verdict v = s.filter.check(rx.data, at, q);
  if (v == Verdict::Accepted) {
    PoseSample p;
    p.sequence = rx.data.sequence_number;
    p.source_time_ns = rx.data.source_time_ns;
    p.tool = s.tool;
    for (int i = 0; i < 3; ++i) p.position_m[i] = rx.data.position_m[i];
    for (int i = 0; i < 4; ++i) p.orientation[i] = q[i];
    s.pose.publish(p);
    if (opt.step_mode == StepMode::kEvent) sem_post(&step_wake);  // wake the step thread
    s.accepted.fetch_add(1, std::memory_order_relaxed);
    s.last_sequence.store(p.sequence, std::memory_order_relaxed);
    s.last_rejected.store(false, std::memory_order_relaxed);
    return;
  }
  s.last_rejected.store(true, std::memory_order_relaxed);
  switch (v) {
    case Verdict::NonFinite: s.rejected_nonfinite.fetch_add(1, std::memory_order_relaxed); ++rejected_nonfinite; break;
    case Verdict::Jump: s.rejected_jump.fetch_add(1, std::memory_order_relaxed); ++rejected_jump; break;
    case Verdict::Workspace: s.rejected_workspace.fetch_add(1, std::memory_order_relaxed); ++rejected_workspace; break;
    case Verdict::Time: s.rejected_time.fetch_add(1, std::memory_order_relaxed); ++rejected_time; break;
    case Verdict::Sequence: s.rejected_sequence.fetch_add(1, std::memory_order_relaxed); ++rejected_sequence; break;
    case Verdict::Rate: ++rejected_rate; break;
    case Verdict::Accepted: break;
  }
  // A station sending garbage must not flood the log: at most N lines per second per cause.
  limited_log(to_string(v), "station '" + key + "': rejected ToolState " +
                                std::to_string(rx.data.sequence_number) + " (" + to_string(v) +
                                "), keeping the last good pose");
}

// ---------------------------------------------------------------------------------------------
// Step thread.
void Server::Impl::step_loop() {
  try {
    log(common::apply_to_this_thread(opt.threads.at("step")));
    const bool event = opt.step_mode == StepMode::kEvent;
    // Event mode: at most max_step_rate_factor × the scene rate, so a fast station (or a burst)
    // cannot take the CPU from the others; one step serves every station's newest pose.
    const auto min_gap_ns =
        event ? static_cast<std::int64_t>(std::llround(static_cast<double>(period_ns) / opt.max_step_rate_factor))
              : period_ns;
    start_mono_ns = monotonic_ns();
    last_status_mono_ns = start_mono_ns;
    next_viewer_ns = start_mono_ns + viewer_period_ns;
    std::int64_t next = start_mono_ns + period_ns;  // this step's deadline
    std::int64_t last_start = start_mono_ns - min_gap_ns;
    while (run.load(std::memory_order_relaxed)) {
      bool on_sample = false;
      if (event) {
        on_sample = wait_for_sample(next);
        if (on_sample && monotonic_ns() < last_start + min_gap_ns) common::sleep_until_ns(last_start + min_gap_ns);
      } else {
        common::sleep_until_ns(next);
      }
      if (!run.load(std::memory_order_relaxed)) break;
      const std::int64_t t0 = monotonic_ns();
      // A deadline miss: the step starts more than one period after its deadline (clock: the
      // absolute tick; event: one period after the previous step, i.e. no step for 2 periods).
      const std::int64_t late = t0 - next;
      if (late > period_ns) {
        ++deadline_misses;
        // Far behind (e.g. the machine stalled): restart the schedule instead of bursting.
        if (late > 20 * period_ns) next = t0;
      }
      (on_sample ? steps_on_sample : steps_on_deadline).fetch_add(1, std::memory_order_relaxed);
      one_step();
      last_start = t0;
      // After a sample the deadline restarts from this step; idle: absolute deadlines.
      next = on_sample ? t0 + period_ns : next + period_ns;
      const std::int64_t t1 = monotonic_ns();
      if (step_us_count < step_us.size()) step_us[step_us_count++] = 1e-3 * static_cast<double>(t1 - t0);
      if (t1 - last_status_mono_ns >= status_period_ns) {
        publish_status(t1);
      } else if (status_soon.load(std::memory_order_acquire) && t1 - last_status_mono_ns >= 200000000) {
        // A station was refused: tell its client now, not at the next status period.
        publish_status(t1);
      }
    }
  } catch (const std::exception& e) {
    fail("step thread", e);
  }
}

// Event step mode: waits until a pose was handed to a slot (true) or deadline_ns passes (false);
// takes every pending post, so one step serves all the samples that arrived meanwhile.
bool Server::Impl::wait_for_sample(std::int64_t deadline_ns) {
  const timespec ts = common::to_timespec(std::max<std::int64_t>(deadline_ns, 0));
  int rc = 0;
  while ((rc = sem_clockwait(&step_wake, CLOCK_MONOTONIC, &ts)) != 0 && errno == EINTR) {
  }
  if (rc != 0) return false;  // ETIMEDOUT
  while (sem_trywait(&step_wake) == 0) {
  }
  return true;
}

void Server::Impl::retire(int i) {
  auto& s = slots[static_cast<std::size_t>(i)];
  if (s.model_written) models->dispose(*models_out[static_cast<std::size_t>(i)]);
  s.pose.consume();  // drop whatever the last session left
  s.step_joined = false;
  s.step_has_pose = false;
  s.model_written = false;
  s.in_contact.store(false, std::memory_order_relaxed);
  if (rigid) proxies[static_cast<std::size_t>(i)].reset();
  s.state.store(kFree, std::memory_order_release);
}

void Server::Impl::one_step() {
  const std::uint64_t step = steps.load(std::memory_order_relaxed) + 1;
  std::size_t n = 0;
  for (std::size_t i = 0; i < slots.size(); ++i) {
    auto& s = slots[i];
    const int st = s.state.load(std::memory_order_acquire);
    if (st == kLeaving) {
      retire(static_cast<int>(i));
      continue;
    }
    if (st != kActive) continue;
    if (!s.step_joined) {
      s.step_joined = true;
      std::memcpy(models_out[i]->station_id, s.station_id, sizeof(s.station_id));
    }
    if (s.pose.consume()) s.step_has_pose = true;
    if (!s.step_has_pose) continue;
    const PoseSample& p = s.pose.newest();
    ToolPose& tp = poses_by_count[slots.size()][n];  // scratch: copied below
    tp.tip_m = interaction::Vec3(p.position_m[0], p.position_m[1], p.position_m[2]);
    // Shaft axis: the tool frame's +z rotated into the scene frame by q = (w, x, y, z).
    const double w = p.orientation[0], x = p.orientation[1], y = p.orientation[2],
                 z = p.orientation[3];
    tp.axis = interaction::Vec3(2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y));
    tp.tool = p.tool;
    // The physics steps the tool held on the free side of the bone (server-side proxy).
    if (rigid) proxies[i].constrain(tool_shapes[static_cast<std::size_t>(tp.tool)], tp, rigid_planes[i]);
    slot_of_pose[n++] = static_cast<int>(i);
  }
  if (n > 0) {
    auto& poses = poses_by_count[n];
    if (n != slots.size())
      for (std::size_t k = 0; k < n; ++k) poses[k] = poses_by_count[slots.size()][k];
    auto& contacts = contacts_by_count[n];
    interaction::StepStats stats;
    sim->step(poses, contacts, stats);
    const std::int64_t now = dds_time();
    for (std::size_t k = 0; k < n; ++k) {
      const std::size_t i = static_cast<std::size_t>(slot_of_pose[k]);
      auto& s = slots[i];
      const PoseSample& p = s.pose.newest();
      const ToolContact& c = contacts[k];
      neurosim_ContactModel& cm = *models_out[i];
      cm.tool_sequence = p.sequence;
      cm.tool_source_time_ns = p.source_time_ns;
      for (int d = 0; d < 3; ++d) {
        cm.x0_position_m[d] = c.in_contact ? c.reference_tip_m[d] : p.position_m[d];
        cm.f0_n[d] = c.in_contact ? c.force_n[d] : 0.0;
        cm.normal[d] = c.in_contact ? c.normal[d] : 0.0;
      }
      for (int d = 0; d < 4; ++d) cm.x0_orientation[d] = p.orientation[d];
      for (int r = 0; r < 3; ++r)
        for (int q = 0; q < 3; ++q) cm.stiffness_n_per_m[3 * r + q] = c.in_contact ? c.stiffness_n_per_m(r, q) : 0.0;
      cm.in_contact = c.in_contact;
      cm.validity_radius_m = c.validity_radius_m;
      cm.server_step = step;
      cm.server_time_ns = now;
      const char* mid = (c.in_contact && c.mesh >= 0 && c.mesh < sim->num_meshes())
                            ? sim->mesh_id(c.mesh).c_str()
                            : "";
      std::strncpy(cm.contact_mesh_id, mid, neurosim_ID_MAX);
      cm.contact_mesh_id[neurosim_ID_MAX] = '\0';
      cm.tool_sample_rejected = s.last_rejected.load(std::memory_order_relaxed);
      if (rigid) {
        const interaction::ObstaclePlanes& rp = rigid_planes[i];
        cm.rigid_planes._length = static_cast<std::uint32_t>(rp.count);
        for (int j = 0; j < rp.count; ++j) {
          const auto& src = rp.planes[static_cast<std::size_t>(j)];
          neurosim_RigidPlane& dst = cm.rigid_planes._buffer[j];
          for (int d = 0; d < 3; ++d) {
            dst.point_m[d] = src.point_m[d];
            dst.normal[d] = src.normal[d];
          }
          dst.penetration_m = src.penetration_m;
        }
      }
      s.in_contact.store(c.in_contact, std::memory_order_relaxed);
      models->write(cm);
      s.model_written = true;
    }
  }
  steps.store(step, std::memory_order_relaxed);
  if (deformation_output && monotonic_ns() >= next_viewer_ns) {  // the viewer rate, on the clock
    next_viewer_ns = std::max(next_viewer_ns + viewer_period_ns, monotonic_ns());
    publish_deformation(step, dds_time());
  }
}

void Server::Impl::publish_deformation(std::uint64_t step, std::int64_t now_ns) {
  const std::uint32_t matched = deformations->matched_readers();
  // A viewer that just matched decodes from the next frame on.
  if (matched > last_matched_viewers) full_frame_pending = true;
  last_matched_viewers = matched;
  if (matched == 0) return;
  // Worker still on the previous frame: skip this one rather than wait.
  if (field_busy.load(std::memory_order_acquire)) {
    ++deformation_skipped;
    return;
  }
  // Once per status period the frame's fields are also measured for the largest strain.
  const bool strain = strain_due.load(std::memory_order_relaxed);
  if (strain) strain_due.store(false, std::memory_order_relaxed);
  sim->snapshot(field_snapshot);
  field_busy.store(true, std::memory_order_release);
  {
    std::lock_guard<std::mutex> lk(field_mutex);
    field_job_step = step;
    field_job_time_ns = now_ns;
    field_job_strain = strain;
    field_job = true;
  }
  field_cv.notify_one();
}

void Server::Impl::encode_and_write(std::uint64_t step, std::int64_t now_ns, bool strain) {
  if (full_frame_pending.exchange(false))
    for (auto& e : encoders) e.force_full_next();
  double max_strain = 0.0;
  for (int m = 0; m < sim->num_meshes(); ++m) {
    auto& u = u_m[static_cast<std::size_t>(m)];
    sim->displacements(field_snapshot, m, u);
    ++full_field_solves;
    if (strain && sim->mesh_active(m)) {
      max_strain = std::max(max_strain, fem::max_principal_strain(sim->mesh(m), u).max_strain);
    }
    auto& out = *deform_out[static_cast<std::size_t>(m)];
    encoders[static_cast<std::size_t>(m)].encode(u.data(), static_cast<std::size_t>(u.size()), step,
                                                 now_ns, out);
    deformations->write(out);
    deform_written[static_cast<std::size_t>(m)] = true;
    ++deformation_frames;
  }
  if (strain) field_max_strain.store(max_strain, std::memory_order_relaxed);
}

// Field worker thread: full-field solves and Deformation writes, off the step thread.
void Server::Impl::field_loop() {
  try {
    log(common::apply_to_this_thread(opt.threads.at("field")));
    for (;;) {
      std::uint64_t step = 0;
      std::int64_t t = 0;
      bool strain = false;
      {
        std::unique_lock<std::mutex> lk(field_mutex);
        field_cv.wait(lk, [&] { return field_job || !run.load(); });
        if (!field_job) return;  // stopping
        field_job = false;
        step = field_job_step;
        t = field_job_time_ns;
        strain = field_job_strain;
      }
      encode_and_write(step, t, strain);
      field_busy.store(false, std::memory_order_release);
    }
  } catch (const std::exception& e) {
    fail("field worker thread", e);
  }
}

void Server::Impl::publish_status(std::int64_t now_mono) {
  const std::size_t n = step_us_count;
  auto& st = *status;
  if (n > 0) {
    std::copy(step_us.begin(), step_us.begin() + static_cast<std::ptrdiff_t>(n), step_us_sorted.begin());
    auto b = step_us_sorted.begin();
    auto e = b + static_cast<std::ptrdiff_t>(n);
    const auto at = [&](double q) { return common::percentile_in_place(b, e, q); };
    st.step_time_p50_us = at(0.5);
    st.step_time_p99_us = at(0.99);
    st.step_time_max_us = *std::max_element(b, e);
  }
  const std::uint64_t s_now = steps.load(std::memory_order_relaxed);
  const double dt = 1e-9 * static_cast<double>(now_mono - last_status_mono_ns);
  st.step_rate_measured_hz = dt > 0 ? static_cast<double>(s_now - steps_at_last_status) / dt : 0.0;
  steps_at_last_status = s_now;
  last_status_mono_ns = now_mono;
  step_us_count = 0;
  // Tier and its update rate from the simulation at every publish: the rate changes while it
  // runs (it is measured over the last second by the tier's own thread).
  st.tier = wire_tier(sim->tier());
  st.tier_update_rate_hz = sim->tier_update_rate_hz();
  report_accuracy(st);
  st.steps = s_now;
  st.deadline_misses = deadline_misses.load();
  st.server_time_ns = dds_time();
  st.uptime_s = 1e-9 * static_cast<double>(now_mono - start_mono_ns);
  std::size_t k = 0;
  for (std::size_t i = 0; i < slots.size(); ++i) {
    auto& s = slots[i];
    if (s.state.load(std::memory_order_acquire) != kActive) continue;
    auto& ss = station_status[k++];
    std::memcpy(ss.station_id, s.station_id, sizeof(ss.station_id));
    ss.alive = true;
    ss.in_contact = s.in_contact.load(std::memory_order_relaxed);
    ss.samples_accepted = s.accepted.load(std::memory_order_relaxed);
    ss.samples_rejected_nonfinite = s.rejected_nonfinite.load(std::memory_order_relaxed);
    ss.samples_rejected_jump = s.rejected_jump.load(std::memory_order_relaxed);
    ss.last_sequence = s.last_sequence.load(std::memory_order_relaxed);
    ss.samples_rejected_workspace = s.rejected_workspace.load(std::memory_order_relaxed);
    ss.samples_rejected_time = s.rejected_time.load(std::memory_order_relaxed);
    ss.samples_rejected_sequence = s.rejected_sequence.load(std::memory_order_relaxed);
    ss.samples_rejected_identity = s.rejected_identity.load(std::memory_order_relaxed);
  }
  wire::assign(st.stations, station_status.data(), k);
  st.samples_rejected_nonfinite = rejected_nonfinite.load();
  st.samples_rejected_jump = rejected_jump.load();
  st.stations_refused = stations_refused.load();
  st.samples_rejected_workspace = rejected_workspace.load();
  st.samples_rejected_time = rejected_time.load();
  st.samples_rejected_sequence = rejected_sequence.load();
  st.samples_rejected_identity = rejected_identity();
  st.samples_rejected_rate = rejected_rate.load();
  st.stations_reclaimed = stations_reclaimed.load();
  st.unknown_ids_dropped = unknown_ids_dropped.load();
  st.log_lines_suppressed = log_limit ? suppressed_lines.load(std::memory_order_relaxed) : 0;
  status_soon.store(false, std::memory_order_release);
  {
    std::lock_guard<std::mutex> lk(refusal_mutex);
    wire::assign(st.refused, refusals.data(), refusals.size());
  }
  status_writer->write(st);
}

// Step thread, at each status: the strain the field thread measured in the fields it solved for
// the viewers since the last one (no viewer: no field is solved, nothing is measured: -1), the
// tier's expected error there, failed equilibrium updates; warnings logged once.
void Server::Impl::report_accuracy(neurosim_SimStatus& st) {
  if (deformation_output) strain_due.store(true, std::memory_order_relaxed);
  if (last_matched_viewers == 0) field_max_strain.store(-1.0, std::memory_order_relaxed);
  const double strain = field_max_strain.load(std::memory_order_relaxed);
  st.max_strain = strain;
  st.expected_force_error = -1.0;
  if (accuracy && strain >= 0.0) {
    const ExpectedError e = accuracy->expected(sim->tier(), strain, settings.name);
    if (e.known) {
      st.expected_force_error = e.force_rel_error;
      if (e.beyond_table && !beyond_table_noted) {
        beyond_table_noted = true;
        std::ostringstream msg;
        msg << "note: strain " << 100.0 * strain << " % is beyond the accuracy table's measured "
            << "strains for tier " << scene::tier_name(sim->tier()) << " (" << e.basis
            << "): the expected force error reported is the largest measured, "
            << 100.0 * e.force_rel_error << " %, and may be exceeded";
        log(msg.str());
      }
      const double bound = settings.effects.max_expected_force_error;
      if (bound > 0.0 && e.force_rel_error > bound && !error_bound_warned) {
        error_bound_warned = true;
        std::ostringstream msg;
        msg << "warning: tier " << scene::tier_name(sim->tier()) << " at strain "
            << 100.0 * strain << " %: expected tool-force error ~" << 100.0 * e.force_rel_error
            << " % exceeds the scene's bound effects.max_expected_force_error = " << 100.0 * bound
            << " % (measured table, " << e.basis << "); a higher tier would be closer "
            << "(docs/accuracy.md)";
        log(msg.str());
      }
    }
  }
  const std::uint64_t failures = sim->tier_update_failures();
  st.tier_update_failures = failures;
  if (failures > tier_failures_logged) {
    log("warning: " + std::to_string(failures - tier_failures_logged) +
        " equilibrium update(s) of tier " + scene::tier_name(sim->tier()) +
        " failed since the last status (the previous equilibrium stays); last: " +
        sim->tier_last_error());
    tier_failures_logged = failures;
  }
}

void Server::Impl::dispose_all() {
  // Clients see the server leave: every instance we wrote is disposed.
  for (std::size_t i = 0; i < slots.size(); ++i)
    if (slots[i].model_written) {
      models->dispose(*models_out[i]);
      slots[i].model_written = false;
    }
  for (std::size_t m = 0; m < deform_out.size(); ++m)
    if (deform_written[m]) {
      wire::set_string(deform_out[m]->mesh_id, sim->mesh_id(static_cast<int>(m)), "mesh_id");
      deformations->dispose(*deform_out[m]);
    }
  if (topologies)
    for (int m = 0; m < sim->num_meshes(); ++m) {
      wire::Sample<neurosim_MeshTopology> k;
      wire::set_string(k->mesh_id, sim->mesh_id(m), "mesh_id");
      topologies->dispose(*k);
    }
  if (topologies)
    for (const scene::RigidSurface& r : rigid_surfaces) {
      wire::Sample<neurosim_MeshTopology> k;
      wire::set_string(k->mesh_id, r.id, "mesh_id");
      topologies->dispose(*k);
    }
  if (status_writer) status_writer->dispose(*status);
}

// ---------------------------------------------------------------------------------------------
Server::Server(const scene::Model& model, std::unique_ptr<interaction::Simulation> sim,
               ServerOptions options, std::ostream& log)
    : impl_(std::make_unique<Impl>(model, std::move(sim), std::move(options), log)) {
  impl_->configure();
}

Server::~Server() {
  try {
    stop();
  } catch (const std::exception& e) {
    impl_->log(std::string("error while stopping: ") + e.what());
  }
  sem_destroy(&impl_->step_wake);
}

const char* step_mode_name(StepMode m) { return m == StepMode::kEvent ? "event" : "clock"; }

common::ThreadPlan default_server_threads() {
  common::ThreadPlan p;
  p.threads = {{"step", "ns-step", 50, {}}, {"dds", "ns-dds", 45, {}}, {"field", "ns-field", 0, {}}};
  return p;
}

void Server::start() {
  auto& d = *impl_;
  if (d.started.exchange(true)) throw std::logic_error("Server::start called twice");
  d.create_entities();
  d.publish_topologies();
  d.run = true;
  d.publish_status(0);  // so SimStatus is readable before the first status period
  d.step_us_count = 0;
  d.dds_thread = std::thread([&d] { d.dds_loop(); });
  d.step_thread = std::thread([&d] { d.step_loop(); });
  if (d.deformation_output) d.field_thread = std::thread([&d] { d.field_loop(); });
  d.log("serving (DDS domain " + (d.opt.domain >= 0 ? std::to_string(d.opt.domain) : std::string("default")) +
        ", server id '" + d.opt.server_id + "')");
}

void Server::stop() {
  auto& d = *impl_;
  if (!d.started.load() || d.stopped.exchange(true)) return;
  d.run = false;
  if (d.waitset) d.waitset->wake();
  sem_post(&d.step_wake);  // the step thread need not wait for its deadline
  if (d.dds_thread.joinable()) d.dds_thread.join();
  if (d.step_thread.joinable()) d.step_thread.join();
  {
    std::lock_guard<std::mutex> lk(d.field_mutex);  // so the worker cannot miss the wake-up
  }
  d.field_cv.notify_all();
  if (d.field_thread.joinable()) d.field_thread.join();
  try {
    d.dispose_all();
  } catch (const std::exception& e) {
    d.log(std::string("error disposing instances: ") + e.what());
  }
  d.log("stopped after " + std::to_string(d.steps.load()) + " steps (" +
        std::to_string(d.deadline_misses.load()) + " deadline misses, rejected " +
        std::to_string(d.rejected_nonfinite.load()) + " non-finite + " +
        std::to_string(d.rejected_jump.load()) + " jump + " + std::to_string(d.rejected_workspace.load()) +
        " workspace + " + std::to_string(d.rejected_time.load()) + " time + " +
        std::to_string(d.rejected_sequence.load()) + " sequence + " + std::to_string(d.rejected_identity()) +
        " identity + " + std::to_string(d.rejected_rate.load()) + " rate samples, reclaimed " +
        std::to_string(d.stations_reclaimed.load()) + " idle stations, refused " +
        std::to_string(d.stations_refused.load()) + " stations; " +
        std::to_string(d.deformation_frames.load()) + " Deformation frames, " +
        std::to_string(d.deformation_skipped.load()) + " viewer ticks skipped); " +
        step_mode_name(d.opt.step_mode) + " step mode: " + std::to_string(d.steps_on_sample.load()) +
        " steps on a sample, " + std::to_string(d.steps_on_deadline.load()) + " on the deadline");
}

bool Server::running() const { return impl_->run.load(); }

std::string Server::error() const {
  std::lock_guard<std::mutex> lk(impl_->error_mutex);
  return impl_->error_text;
}

ServerCounters Server::counters() const {
  const auto& d = *impl_;
  ServerCounters c;
  c.steps = d.steps.load();
  c.deadline_misses = d.deadline_misses.load();
  c.rejected_nonfinite = d.rejected_nonfinite.load();
  c.rejected_jump = d.rejected_jump.load();
  c.stations_refused = d.stations_refused.load();
  c.rejected_workspace = d.rejected_workspace.load();
  c.rejected_time = d.rejected_time.load();
  c.rejected_sequence = d.rejected_sequence.load();
  c.rejected_identity = d.rejected_identity();
  c.rejected_rate = d.rejected_rate.load();
  c.stations_reclaimed = d.stations_reclaimed.load();
  c.deformation_frames = d.deformation_frames.load();
  c.full_field_solves = d.full_field_solves.load();
  c.deformation_skipped = d.deformation_skipped.load();
  c.steps_on_sample = d.steps_on_sample.load();
  c.steps_on_deadline = d.steps_on_deadline.load();
  return c;
}

}  // namespace neurosim::service
