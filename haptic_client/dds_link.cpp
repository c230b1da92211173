#include "haptic_client/dds_link.hpp"

#include "common/clock.hpp"
#include "common/thread_sched.hpp"
#include "idl/wire/client.hpp"
#include "idl/wire/dds.hpp"

#include <pthread.h>
#include <sched.h>
#include <semaphore.h>
#include <time.h>

#include <array>
#include <cstring>

namespace neurosim::haptic {

namespace {
using common::realtime_ns;
using common::monotonic_ns;
constexpr dds_attach_t kModels = 1;
constexpr dds_attach_t kStatus = wire::ClientSession::kStatusData;
constexpr dds_attach_t kStatusLiveliness = wire::ClientSession::kStatusLiveliness;
}  // namespace

struct DdsLink::Impl {
  DdsLinkOptions opt;
  // The shared client set-up (participant, prefixed topics, the server's SimStatus and its
  // liveliness on the waitset) plus this station's ToolState writer and ContactModel reader.
  wire::ClientSession session;
  wire::Topic<neurosim_ToolState> tool_topic;
  wire::Writer<neurosim_ToolState> tools;
  wire::Topic<neurosim_ContactModel> model_topic;
  wire::Reader<neurosim_ContactModel> models;
  wire::Reader<neurosim_SimStatus>& status;
  wire::Waitset& ws;
  wire::Sample<neurosim_ToolState> sample;
  std::array<std::uint8_t, 16> own_writer{};  // to recognise this station in SimStatus.refused
  sem_t pending;  // posted by publish() (async-signal-safe, no lock in the loop thread)

  explicit Impl(const DdsLinkOptions& o)
      : opt(o),
        session(wire::ClientOptions{-1, o.topic_prefix}),
        tool_topic(session.topic<neurosim_ToolState>()),
        tools(session.participant(), tool_topic, o.station_id),  // in partition neurosim.station.<station_id>
        model_topic(session.topic<neurosim_ContactModel>()),
        models(session.participant(), model_topic),
        status(session.status()),
        ws(session.waitset()) {
    wire::set_string(sample->station_id, o.station_id, "station_id");
    wire::set_string(sample->tool_id, o.tool_id, "tool_id");
    own_writer = tools.guid();
    ws.attach_data(models, kModels);
    sem_init(&pending, 0, 0);
  }
  ~Impl() { sem_destroy(&pending); }
};

DdsLink::DdsLink(const DdsLinkOptions& options) {
  if (options.station_id.empty()) throw std::invalid_argument("haptic DDS link: empty station id");
  impl_ = std::make_unique<Impl>(options);
  thread_ = std::thread([this] { run(); });
  publisher_ = std::thread([this] { run_publisher(); });
}

DdsLink::~DdsLink() {
  stop_ = true;
  if (impl_) {
    impl_->ws.wake();
    sem_post(&impl_->pending);
  }
  if (thread_.joinable()) thread_.join();
  if (publisher_.joinable()) publisher_.join();
}

void DdsLink::publish(const ToolSample& s) {
  outgoing_.publish(s);
  sem_post(&impl_->pending);
}

void DdsLink::run_publisher() {
  {  // best effort: normal priority if refused (said in the line)
    const auto& o = impl_->opt;
    const std::string line = common::apply_to_this_thread(
        {"publisher", o.publisher_thread_name, o.publisher_rt_priority, o.publisher_cpus});
    if (o.sched_log != nullptr) o.sched_log(line.c_str());
  }
  ToolSample s;
  neurosim_ToolState& t = *impl_->sample;
  while (!stop_.load()) {
    if (sem_wait(&impl_->pending) != 0) continue;  // EINTR
    if (stop_.load()) break;
    if (!outgoing_.take(s)) continue;  // several posts, one newest sample: already sent
    for (int i = 0; i < 3; ++i) {
      t.position_m[i] = s.position_m[i];
      t.velocity_m_per_s[i] = s.velocity_m_per_s[i];
    }
    for (int i = 0; i < 4; ++i) t.orientation[i] = s.orientation[i];
    t.buttons = s.buttons;
    t.sequence_number = s.sequence_number;
    t.source_time_ns = s.source_time_ns;
    try {
      impl_->tools.write(t, s.source_time_ns);
    } catch (const std::exception&) {
      write_errors_.fetch_add(1);  // counted; the loop's watchdog handles missing answers
    }
  }
}

std::size_t copy_contact_model(const neurosim_ContactModel& c, std::int64_t arrival_ns,
                               ContactModelData& m) {
  m.tool_sequence = c.tool_sequence;
  // Age is measured against the pose the model answers (same machine clock); fall back to
  // arrival time if the server did not echo it.
  m.reference_time_ns = c.tool_source_time_ns > 0 ? c.tool_source_time_ns : arrival_ns;
  for (int i = 0; i < 3; ++i) {
    m.x0_m[i] = c.x0_position_m[i];
    m.f0_n[i] = c.f0_n[i];
    m.normal[i] = c.normal[i];
  }
  for (int i = 0; i < 9; ++i) m.k_n_per_m(i / 3, i % 3) = c.stiffness_n_per_m[i];
  m.in_contact = c.in_contact;
  m.validity_radius_m = c.validity_radius_m;
  m.server_step = c.server_step;
  // Relaxing parts into the fixed array (the IDL bounds the sequence to kMaxRelaxingForces; the
  // force model rejects a model with a non-finite part or tau_s <= 0).
  m.num_relaxing = 0;
  for (const neurosim_RelaxingForce& r : wire::view(c.relaxing_forces)) {
    if (m.num_relaxing == kMaxRelaxingForces) break;
    RelaxingForce& dst = m.relaxing[m.num_relaxing++];
    dst.force_n = Eigen::Vector3d(r.force_n[0], r.force_n[1], r.force_n[2]);
    dst.tau_s = r.tau_s;
  }
  // Rigid planes into the fixed array (the IDL bounds the sequence to kMaxRigidPlanes).
  std::size_t dropped = 0;
  m.rigid_planes.clear();
  for (const neurosim_RigidPlane& p : wire::view(c.rigid_planes))
    if (!m.rigid_planes.add(p.point_m, p.normal, p.penetration_m)) ++dropped;
  return dropped;
}

DdsLinkCounters DdsLink::counters() const {
  DdsLinkCounters c;
  c.models_received = models_.load();
  c.models_rejected = rejected_.load();
  c.server_lost = lost_.load();
  c.server_seen = seen_.load();
  c.write_errors = write_errors_.load();
  c.models_skipped = skipped_.load();
  c.planes_dropped = planes_dropped_.load();
  return c;
}

const char* describe(Refusal r) {
  switch (r) {
    case Refusal::None: return "not refused";
    case Refusal::MaxStations:
      return "the server's station slots are all taken (max_stations); waiting for a free slot";
    case Refusal::ParticipantLimit:
      return "this DDS participant already holds the server's maximum of stations per participant";
    case Refusal::Identity:
      return "the station id is held by another writer (another neurosim-haptic with the same "
             "--station?), or this writer's partition does not claim it";
  }
  return "unknown";
}

Refusal DdsLink::refusal() const {
  const auto r = static_cast<Refusal>(refusal_.load(std::memory_order_acquire));
  if (r == Refusal::None) return r;
  if (realtime_ns() - refusal_time_ns_.load(std::memory_order_relaxed) > 2000000000) return Refusal::None;
  return r;
}

bool DdsLink::wait_for_server(double timeout_s) const {
  return impl_->models.wait_for_writers(1, static_cast<dds_duration_t>(timeout_s * 1e9));
}

void DdsLink::run() {
  Impl& im = *impl_;
  {  // best effort: normal priority if refused (said in the line)
    const auto& o = im.opt;
    const std::string line = common::apply_to_this_thread(
        {"receiver", o.receiver_thread_name, o.receiver_rt_priority, o.receiver_cpus});
    if (o.sched_log != nullptr) o.sched_log(line.c_str());
  }
  ContactModelData m;
  bool had_writer = false;
  // Liveliness lost but a model arrived within this time: the server is alive (unit ns).
  constexpr std::int64_t kModelProvesLifeNs = 100'000'000;
  std::int64_t last_model_ns = 0;
  std::uint64_t last_server_step = 0;
  while (!stop_.load()) {
    const auto r = im.ws.wait(DDS_MSECS(20));
    if (stop_.load()) break;
    if (const neurosim_ContactModel* c = im.models.take_newest(im.opt.station_id)) {
      if (const std::size_t dropped = copy_contact_model(*c, realtime_ns(), m))
        planes_dropped_.fetch_add(dropped);
      // Gaps in the server's step count (a restarted server starts again from 1: no gap).
      if (last_server_step > 0 && c->server_step > last_server_step + 1)
        skipped_.fetch_add(c->server_step - last_server_step - 1);
      last_server_step = c->server_step;
      if (c->tool_sample_rejected) rejected_.fetch_add(1);
      models_.fetch_add(1);
      slot_.publish(m);
      // A fresh model is itself proof of life: after a stall (SIGSTOP, a frozen machine) the
      // server's liveliness comes back up to a lease later, the force need not wait for it.
      last_model_ns = monotonic_ns();
      if (had_writer && !alive_.load()) {
        alive_.store(true, std::memory_order_release);
        seen_.fetch_add(1);
      }
    }
    if (r.has(kStatus)) {
      // Server health comes from liveliness; the content says whether this station was refused.
      for (const auto& rx : im.status.take()) {
        if (!rx.valid()) continue;
        for (const auto& f : wire::view(rx.data.refused)) {
          if (im.opt.station_id != f.station_id ||
              std::memcmp(f.writer_guid, im.own_writer.data(), 16) != 0)
            continue;
          const Refusal why = f.reason == neurosim_REFUSED_MAX_STATIONS       ? Refusal::MaxStations
                              : f.reason == neurosim_REFUSED_PARTICIPANT_LIMIT ? Refusal::ParticipantLimit
                                                                               : Refusal::Identity;
          refusal_time_ns_.store(f.time_ns, std::memory_order_relaxed);
          refusal_.store(static_cast<int>(why), std::memory_order_release);
        }
      }
    }
    if (r.has(kStatusLiveliness) || r.timed_out()) {
      if (im.session.server_alive()) {
        if (!had_writer || !alive_.load()) seen_.fetch_add(1);
        had_writer = true;
        alive_.store(true, std::memory_order_release);
      } else if (had_writer && alive_.load() &&
                 monotonic_ns() - last_model_ns > kModelProvesLifeNs) {
        alive_.store(false, std::memory_order_release);  // server gone: loop zeroes the force
        lost_.fetch_add(1);
      }
    }
  }
}

}  // namespace neurosim::haptic
