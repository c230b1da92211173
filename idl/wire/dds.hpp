// Thin RAII C++ over the Cyclone DDS C API: Participant, Topic<T>, Writer<T>, Reader<T>, Waitset.
// Every failing DDS call throws std::runtime_error naming the call's purpose and the DDS reason.
//
//   wire::Participant pp;                                  // refuses to start w/o CYCLONEDDS_URI
//   wire::Topic<neurosim_ToolState> topic(pp);             // name + QoS from TopicTraits / qos.cpp
//   wire::Writer<neurosim_ToolState> w(pp, topic);
//   wire::Sample<neurosim_ToolState> s;  wire::set_string(s->station_id, "omni-1");  w.write(*s);
//   wire::Reader<neurosim_ToolState> r(pp, topic);
//   for (const auto& rx : r.take()) { if (rx.valid()) use(rx.data); else if (rx.disposed()) ... }
//
// Thread safety: the C API is thread-safe; one Reader<T> must not be taken from by two threads
// at once (it reuses its sample buffers). Waitset::wake() may be called from any thread but is
// not async-signal-safe (set a flag in the signal handler, wake from a normal thread, or use a
// timeout).
#pragma once

#include "idl/wire/error.hpp"
#include "idl/wire/qos.hpp"
#include "idl/wire/types.hpp"

#include <dds/dds.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace neurosim::wire {

// Owns a DDS entity handle; deleting it deletes its children (a participant its topics, ...).
class Entity {
 public:
  Entity() = default;
  explicit Entity(dds_entity_t h) : h_(h) {}
  ~Entity() { reset(); }
  Entity(const Entity&) = delete;
  Entity& operator=(const Entity&) = delete;
  Entity(Entity&& o) noexcept : h_(std::exchange(o.h_, 0)) {}
  Entity& operator=(Entity&& o) noexcept {
    if (this != &o) {
      reset();
      h_ = std::exchange(o.h_, 0);
    }
    return *this;
  }
  // Deleting an entity whose parent is already gone returns an error: nothing to do then.
  void reset() noexcept {
    if (h_ > 0) dds_delete(h_);
    h_ = 0;
  }
  dds_entity_t get() const { return h_; }

 private:
  dds_entity_t h_ = 0;
};

// The loopback configuration of this source tree: file://<repo>/deploy/cyclonedds/loopback.xml.
std::string loopback_config_uri();

struct ParticipantOptions {
  dds_domainid_t domain = DDS_DOMAIN_DEFAULT;
  // Network rule: every process runs with CYCLONEDDS_URI set (loopback.xml by default). Without
  // it Cyclone would pick any interface with multicast, so the Participant refuses to start
  // unless this is true.
  bool allow_unset_config = false;
};

class Participant {
 public:
  explicit Participant(const ParticipantOptions& options = {});
  dds_entity_t handle() const { return e_.get(); }

 private:
  Entity e_;
};

// ---------------------------------------------------------------------------------------------
// Non-template cores (dds.cpp).
dds_entity_t create_topic(const Participant& pp, const dds_topic_descriptor_t* desc,
                          const std::string& name, Profile profile);

// A DDS entity's GUID as 16 octets (e.g. a writer's, to recognise it in SimStatus.refused).
std::array<std::uint8_t, 16> guid_of(dds_entity_t entity);

// What discovery says of a writer matched with a reader (dds_get_matched_publication_data).
struct MatchedPublication {
  bool matched = false;  // false: no such writer matched (gone, or never was)
  std::array<std::uint8_t, 16> guid{};
  std::array<std::uint8_t, 16> participant_guid{};
  std::vector<std::string> partitions;  // empty: the default partition
};

class WriterBase {
 public:
  dds_entity_t handle() const { return e_.get(); }
  std::array<std::uint8_t, 16> guid() const { return guid_of(e_.get()); }
  const std::string& topic_name() const { return topic_; }
  // Readers currently matched (e.g. publish Deformation only while someone reads).
  std::uint32_t matched_readers() const;
  // Blocks until at least n readers match or the timeout passes; returns whether they did.
  bool wait_for_readers(std::uint32_t n, dds_duration_t timeout) const;

 protected:
  WriterBase(const Participant& pp, dds_entity_t topic, std::string topic_name, const Qos& qos);
  void write_raw(const void* sample, dds_time_t source_time) const;
  void dispose_raw(const void* key_sample) const;
  void unregister_raw(const void* key_sample) const;

 private:
  Entity e_;
  std::string topic_;
};

// What happened to the instance (key) a received sample belongs to.
enum class InstanceChange { None, Disposed, NoWriters };

// liveliness_changed status of a reader (counts of writers alive / not alive, and the changes
// since the previous call: reading resets the *_change fields).
struct Liveliness {
  std::uint32_t alive_count = 0;
  std::uint32_t not_alive_count = 0;
  std::int32_t alive_count_change = 0;
  std::int32_t not_alive_count_change = 0;
  dds_instance_handle_t last_publication_handle = 0;  // the writer of the newest change
  bool changed() const { return alive_count_change != 0 || not_alive_count_change != 0; }
};

struct ReaderOptions {
  std::size_t max_samples = 64;  // taken per take() call; the reader keeps this many buffers
};

class ReaderBase {
 public:
  dds_entity_t handle() const { return e_.get(); }
  const std::string& topic_name() const { return topic_; }
  std::uint32_t matched_writers() const;
  bool wait_for_writers(std::uint32_t n, dds_duration_t timeout) const;
  // Reads (and resets) the liveliness_changed status: a dead writer shows as alive_count
  // dropping (detect death with this, not with instance state: see qos.hpp).
  Liveliness liveliness() const;
  // The matched writer with this instance handle (dds_sample_info_t.publication_handle).
  MatchedPublication matched_publication(dds_instance_handle_t writer) const;

 protected:
  ReaderBase(const Participant& pp, dds_entity_t topic, std::string topic_name, const Qos& qos);
  // dds_take into caller-owned samples; returns the number taken.
  std::size_t take_raw(void** samples, dds_sample_info_t* infos, std::size_t n) const;

 private:
  Entity e_;
  std::string topic_;
};

inline InstanceChange change_of(const dds_sample_info_t& info) {
  if (info.instance_state == DDS_IST_NOT_ALIVE_DISPOSED) return InstanceChange::Disposed;
  if (info.instance_state == DDS_IST_NOT_ALIVE_NO_WRITERS) return InstanceChange::NoWriters;
  return InstanceChange::None;
}

// ---------------------------------------------------------------------------------------------
template <class T>
class Topic {
 public:
  explicit Topic(const Participant& pp, std::string name = topic_name<T>())
      : e_(create_topic(pp, TopicTraits<T>::descriptor(), name, TopicTraits<T>::profile)),
        name_(std::move(name)) {}
  dds_entity_t handle() const { return e_.get(); }
  const std::string& name() const { return name_; }

 private:
  Entity e_;
  std::string name_;
};

template <class T>
class Writer : public WriterBase {
 public:
  // QoS from the topic's profile (qos.cpp). Not for ToolState: see the station constructor.
  Writer(const Participant& pp, const Topic<T>& topic)
      : Writer(pp, topic, writer_qos(TopicTraits<T>::profile)) {
    static_assert(TopicTraits<T>::profile != Profile::ToolState,
                  "a ToolState writer publishes in its station's partition: "
                  "Writer<neurosim_ToolState>(pp, topic, station_id)");
  }
  // ToolState only: the writer of ONE station, in its partition (tool_state_writer_qos).
  Writer(const Participant& pp, const Topic<T>& topic, std::string_view station_id)
      : Writer(pp, topic, tool_state_writer_qos(station_id)) {
    static_assert(TopicTraits<T>::profile == Profile::ToolState,
                  "only ToolState writers are per station");
  }
  Writer(const Participant& pp, const Topic<T>& topic, const Qos& qos)
      : WriterBase(pp, topic.handle(), topic.name(), qos) {}

  // Source timestamp: now (dds_time()).
  void write(const T& s) const { write_raw(&s, DDS_TIME_INVALID); }
  void write(const T& s, dds_time_t source_time_ns) const { write_raw(&s, source_time_ns); }
  // Only the key fields of key_sample are used.
  void dispose(const T& key_sample) const { dispose_raw(&key_sample); }
  void unregister(const T& key_sample) const { unregister_raw(&key_sample); }
};

// One received sample. For invalid samples (valid() false: a state change only) just the key
// fields of data are meaningful.
template <class T>
struct Received {
  const T& data;
  const dds_sample_info_t& info;
  bool valid() const { return info.valid_data; }
  InstanceChange change() const { return change_of(info); }
  bool disposed() const { return change() == InstanceChange::Disposed; }
  bool no_writers() const { return change() == InstanceChange::NoWriters; }
  std::string_view key() const { return TopicTraits<T>::key(data); }
};

// The samples of one take(), pointing into the reader's buffers: valid until the next take.
template <class T>
class Batch {
 public:
  Batch(const T* data, const dds_sample_info_t* infos, std::size_t n)
      : data_(data), infos_(infos), n_(n) {}
  std::size_t size() const { return n_; }
  bool empty() const { return n_ == 0; }
  Received<T> operator[](std::size_t i) const { return {data_[i], infos_[i]}; }

  struct iterator {
    const Batch* b;
    std::size_t i;
    Received<T> operator*() const { return (*b)[i]; }
    iterator& operator++() {
      ++i;
      return *this;
    }
    bool operator!=(const iterator& o) const { return i != o.i; }
  };
  iterator begin() const { return {this, 0}; }
  iterator end() const { return {this, n_}; }

  // Newest valid sample (by source timestamp) whose key is `key` (any key if empty), or null.
  const T* newest(std::string_view key = {}) const {
    const T* best = nullptr;
    dds_time_t best_t = 0;
    for (std::size_t i = 0; i < n_; ++i) {
      if (!infos_[i].valid_data) continue;
      if (!key.empty() && TopicTraits<T>::key(data_[i]) != key) continue;
      if (best == nullptr || infos_[i].source_timestamp >= best_t) {
        best = &data_[i];
        best_t = infos_[i].source_timestamp;
      }
    }
    return best;
  }
  // The strongest instance change among the samples of `key` (any key if empty).
  InstanceChange change(std::string_view key = {}) const {
    InstanceChange c = InstanceChange::None;
    for (std::size_t i = 0; i < n_; ++i) {
      if (!key.empty() && TopicTraits<T>::key(data_[i]) != key) continue;
      const InstanceChange ci = change_of(infos_[i]);
      if (ci == InstanceChange::Disposed) return ci;
      if (ci == InstanceChange::NoWriters) c = ci;
    }
    return c;
  }

 private:
  const T* data_;
  const dds_sample_info_t* infos_;
  std::size_t n_;
};

template <class T>
class Reader : public ReaderBase {
 public:
  Reader(const Participant& pp, const Topic<T>& topic, ReaderOptions options = {})
      : Reader(pp, topic, reader_qos(TopicTraits<T>::profile), options) {}
  Reader(const Participant& pp, const Topic<T>& topic, const Qos& qos, ReaderOptions options = {})
      : ReaderBase(pp, topic.handle(), topic.name(), qos),
        samples_(options.max_samples > 0 ? options.max_samples : 1),
        ptrs_(samples_.size()),
        infos_(samples_.size()) {
    for (std::size_t i = 0; i < samples_.size(); ++i) ptrs_[i] = &samples_[i];
  }
  ~Reader() {
    for (auto& s : samples_) dds_sample_free(&s, TopicTraits<T>::descriptor(), DDS_FREE_CONTENTS);
  }
  Reader(Reader&&) noexcept = default;  // the buffers (and ptrs_ into them) move along
  Reader& operator=(Reader&&) = delete;

  // Takes everything available (at most max_samples). Deserializes into the reader's own
  // samples, whose sequence buffers are reused: no allocation once they are big enough.
  Batch<T> take() {
    const std::size_t n = take_raw(ptrs_.data(), infos_.data(), ptrs_.size());
    return Batch<T>(samples_.data(), infos_.data(), n);
  }
  // take() and keep only the newest valid sample of `key` (any key if empty), or null. Use
  // take() instead when instance changes (disposed, no writers) matter.
  const T* take_newest(std::string_view key = {}) { return take().newest(key); }

 private:
  std::vector<T> samples_;  // value-initialised: empty strings and sequences
  std::vector<void*> ptrs_;
  std::vector<dds_sample_info_t> infos_;
};

// ---------------------------------------------------------------------------------------------
// Blocks a thread until readers have data / a liveliness change, or until wake() (shutdown).
class Waitset {
 public:
  // Token reported when wake() was called; do not use it for attachments.
  static constexpr dds_attach_t kWakeToken = ~dds_attach_t{0};
  static constexpr std::size_t kMaxTriggered = 32;

  struct Result {
    std::array<dds_attach_t, kMaxTriggered> tokens{};  // of the triggered attachments
    std::size_t count = 0;
    bool woken = false;  // wake() was called (and has been reset)
    bool timed_out() const { return count == 0 && !woken; }
    bool has(dds_attach_t token) const {
      for (std::size_t i = 0; i < count; ++i)
        if (tokens[i] == token) return true;
      return false;
    }
  };

  explicit Waitset(const Participant& pp);
  // Triggers while the reader holds samples (any state, including state changes).
  void attach_data(const ReaderBase& reader, dds_attach_t token);
  // Triggers on liveliness_changed until reader.liveliness() is called.
  void attach_liveliness(const ReaderBase& reader, dds_attach_t token);
  Result wait(dds_duration_t timeout);
  void wake();

 private:
  Entity ws_;
  Entity guard_;
  std::vector<Entity> conditions_;
};

}  // namespace neurosim::wire
