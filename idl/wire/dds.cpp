#include "idl/wire/dds.hpp"

#include <algorithm>
#include <chrono>
#include <cstring>
#include <cstdlib>
#include <stdexcept>
#include <thread>

namespace neurosim::wire {

std::string loopback_config_uri() { return NEUROSIM_LOOPBACK_URI; }

std::array<std::uint8_t, 16> guid_of(dds_entity_t entity) {
  dds_guid_t g{};
  check(dds_get_guid(entity, &g), "get GUID of entity");
  std::array<std::uint8_t, 16> out{};
  std::memcpy(out.data(), g.v, 16);
  return out;
}

namespace {

dds_entity_t create_participant(const ParticipantOptions& o) {
  const char* uri = std::getenv("CYCLONEDDS_URI");
  // Network rule: loopback unless a configuration is chosen explicitly
  // (docs/ARCHITECTURE.md "DDS").
  if ((uri == nullptr || *uri == '\0') && !o.allow_unset_config)
    throw std::runtime_error(
        "CYCLONEDDS_URI is not set: refusing to start DDS on Cyclone's default network "
        "configuration. Run with CYCLONEDDS_URI=" +
        loopback_config_uri() + " (or deploy/cyclonedds/lan.xml for a real deployment)");
  return check(dds_create_participant(o.domain, nullptr, nullptr),
               "create participant (CYCLONEDDS_URI=" + std::string(uri ? uri : "") + ")");
}

}  // namespace

Participant::Participant(const ParticipantOptions& options) : e_(create_participant(options)) {}

dds_entity_t create_topic(const Participant& pp, const dds_topic_descriptor_t* desc,
                          const std::string& name, Profile profile) {
  const Qos q = topic_qos(profile);
  return check(dds_create_topic(pp.handle(), desc, name.c_str(), q.get(), nullptr),
               "create topic " + name + " (" + desc->m_typename + ")");
}

namespace {

// Polls: matched counts have no cheap blocking wait that does not disturb status masks.
template <class F>
void wait_until(dds_duration_t timeout, F done) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::nanoseconds(timeout);
  while (!done() && std::chrono::steady_clock::now() < end)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
}

}  // namespace

// ---------------------------------------------------------------------------------------------
WriterBase::WriterBase(const Participant& pp, dds_entity_t topic, std::string topic_name,
                       const Qos& qos)
    : e_(check(dds_create_writer(pp.handle(), topic, qos.get(), nullptr),
               "create writer on " + topic_name)),
      topic_(std::move(topic_name)) {}

void WriterBase::write_raw(const void* sample, dds_time_t source_time) const {
  const dds_return_t rc = source_time == DDS_TIME_INVALID
                              ? dds_write(e_.get(), sample)
                              : dds_write_ts(e_.get(), sample, source_time);
  if (rc < 0) throw_dds_error(rc, "write " + topic_);
}

void WriterBase::dispose_raw(const void* key_sample) const {
  const dds_return_t rc = dds_dispose(e_.get(), key_sample);
  if (rc < 0) throw_dds_error(rc, "dispose instance of " + topic_);
}

void WriterBase::unregister_raw(const void* key_sample) const {
  const dds_return_t rc = dds_unregister_instance(e_.get(), key_sample);
  if (rc < 0) throw_dds_error(rc, "unregister instance of " + topic_);
}

std::uint32_t WriterBase::matched_readers() const {
  dds_publication_matched_status_t st{};
  // No message string unless it fails: this is polled from the step loop.
  const dds_return_t rc = dds_get_publication_matched_status(e_.get(), &st);
  if (rc < 0) throw_dds_error(rc, "get publication matched status of " + topic_);
  return st.current_count;
}

bool WriterBase::wait_for_readers(std::uint32_t n, dds_duration_t timeout) const {
  wait_until(timeout, [&] { return matched_readers() >= n; });
  return matched_readers() >= n;
}

// ---------------------------------------------------------------------------------------------
ReaderBase::ReaderBase(const Participant& pp, dds_entity_t topic, std::string topic_name,
                       const Qos& qos)
    : e_(check(dds_create_reader(pp.handle(), topic, qos.get(), nullptr),
               "create reader on " + topic_name)),
      topic_(std::move(topic_name)) {}

std::size_t ReaderBase::take_raw(void** samples, dds_sample_info_t* infos, std::size_t n) const {
  const dds_return_t rc =
      dds_take(e_.get(), samples, infos, n, static_cast<std::uint32_t>(n));
  if (rc < 0) throw_dds_error(rc, "take from " + topic_);
  return static_cast<std::size_t>(rc);
}

std::uint32_t ReaderBase::matched_writers() const {
  dds_subscription_matched_status_t st{};
  const dds_return_t rc = dds_get_subscription_matched_status(e_.get(), &st);
  if (rc < 0) throw_dds_error(rc, "get subscription matched status of " + topic_);
  return st.current_count;
}

bool ReaderBase::wait_for_writers(std::uint32_t n, dds_duration_t timeout) const {
  wait_until(timeout, [&] { return matched_writers() >= n; });
  return matched_writers() >= n;
}

Liveliness ReaderBase::liveliness() const {
  dds_liveliness_changed_status_t st{};
  const dds_return_t rc = dds_get_liveliness_changed_status(e_.get(), &st);
  if (rc < 0) throw_dds_error(rc, "get liveliness changed status of " + topic_);
  Liveliness l;
  l.alive_count = st.alive_count;
  l.not_alive_count = st.not_alive_count;
  l.alive_count_change = st.alive_count_change;
  l.not_alive_count_change = st.not_alive_count_change;
  l.last_publication_handle = st.last_publication_handle;
  return l;
}

MatchedPublication ReaderBase::matched_publication(dds_instance_handle_t writer) const {
  MatchedPublication m;
  dds_builtintopic_endpoint_t* ep = dds_get_matched_publication_data(e_.get(), writer);
  if (ep == nullptr) return m;
  m.matched = true;
  std::memcpy(m.guid.data(), ep->key.v, 16);
  std::memcpy(m.participant_guid.data(), ep->participant_key.v, 16);
  m.partitions = partitions_of(ep->qos);
  dds_builtintopic_free_endpoint(ep);
  return m;
}

// ---------------------------------------------------------------------------------------------
Waitset::Waitset(const Participant& pp)
    : ws_(check(dds_create_waitset(pp.handle()), "create waitset")),
      guard_(check(dds_create_guardcondition(pp.handle()), "create guard condition")) {
  check(dds_waitset_attach(ws_.get(), guard_.get(), kWakeToken), "attach guard condition");
}

void Waitset::attach_data(const ReaderBase& reader, dds_attach_t token) {
  if (token == kWakeToken) throw std::invalid_argument("Waitset: token kWakeToken is reserved");
  Entity cond(check(dds_create_readcondition(reader.handle(), DDS_ANY_STATE),
                    "create read condition on " + reader.topic_name()));
  check(dds_waitset_attach(ws_.get(), cond.get(), token),
        "attach read condition of " + reader.topic_name());
  conditions_.push_back(std::move(cond));
}

void Waitset::attach_liveliness(const ReaderBase& reader, dds_attach_t token) {
  if (token == kWakeToken) throw std::invalid_argument("Waitset: token kWakeToken is reserved");
  check(dds_set_status_mask(reader.handle(), DDS_LIVELINESS_CHANGED_STATUS),
        "set status mask of " + reader.topic_name());
  check(dds_waitset_attach(ws_.get(), reader.handle(), token),
        "attach liveliness status of " + reader.topic_name());
}

Waitset::Result Waitset::wait(dds_duration_t timeout) {
  Result r;
  const dds_return_t n =
      check(dds_waitset_wait(ws_.get(), r.tokens.data(), r.tokens.size(), timeout),
            "wait on waitset");
  const std::size_t got = std::min<std::size_t>(static_cast<std::size_t>(n), r.tokens.size());
  // Report the guard separately and reset it so the next wait blocks again.
  for (std::size_t i = 0; i < got; ++i) {
    if (r.tokens[i] == kWakeToken) {
      r.woken = true;
      check(dds_set_guardcondition(guard_.get(), false), "reset guard condition");
    } else {
      r.tokens[r.count++] = r.tokens[i];
    }
  }
  return r;
}

void Waitset::wake() { check(dds_set_guardcondition(guard_.get(), true), "trigger guard condition"); }

}  // namespace neurosim::wire
