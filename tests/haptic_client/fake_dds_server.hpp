// Test-only stand-in for neurosim-server over DDS (tests and bench/haptic_bench): a thread with
// its own participant answering each ToolState at once with the half-space ContactModel, and
// writing SimStatus every 100 ms (liveliness). kill() deletes every entity abruptly.
#pragma once

#include "fake_server.hpp"
#include "idl/wire/dds.hpp"

#include <atomic>
#include <chrono>
#include <memory>
#include <string>
#include <thread>

namespace neurosim::haptic::testing {

namespace wire = neurosim::wire;
using Eigen::Vector3d;

// Answers every ToolState at once with the half-space model; SimStatus every 100 ms.
class FakeDdsServer {
 public:
  FakeDdsServer(const std::string& topic_prefix, HalfSpace tissue) : tissue_(tissue) {
    pp_ = std::make_unique<wire::Participant>();
    tt_ = std::make_unique<wire::Topic<neurosim_ToolState>>(*pp_, wire::topic_name<neurosim_ToolState>(topic_prefix));
    tools_ = std::make_unique<wire::Reader<neurosim_ToolState>>(*pp_, *tt_);
    mt_ = std::make_unique<wire::Topic<neurosim_ContactModel>>(*pp_, wire::topic_name<neurosim_ContactModel>(topic_prefix));
    models_ = std::make_unique<wire::Writer<neurosim_ContactModel>>(*pp_, *mt_);
    st_ = std::make_unique<wire::Topic<neurosim_SimStatus>>(*pp_, wire::topic_name<neurosim_SimStatus>(topic_prefix));
    status_ = std::make_unique<wire::Writer<neurosim_SimStatus>>(*pp_, *st_);
    ws_ = std::make_unique<wire::Waitset>(*pp_);
    ws_->attach_data(*tools_, 1);
    thread_ = std::thread([this] { run(); });
  }
  // Abrupt end: stop answering and delete every entity (as far as the client can tell, gone).
  ~FakeDdsServer() { kill(); }
  void kill() {
    if (!pp_) return;
    stop_ = true;
    ws_->wake();
    thread_.join();
    ws_.reset();
    status_.reset();
    models_.reset();
    tools_.reset();
    st_.reset();
    mt_.reset();
    tt_.reset();
    pp_.reset();
  }
  std::uint64_t answered() const { return answered_.load(); }
  std::atomic<bool> answering{true};  // false: alive (SimStatus) but silent, as a stalled server

 private:
  void run() {
    wire::Sample<neurosim_ContactModel> cm;
    wire::Sample<neurosim_SimStatus> st;
    wire::set_string(st->server_id, "fake");
    auto last_status = std::chrono::steady_clock::now() - std::chrono::seconds(1);
    std::uint64_t step = 0;
    while (!stop_) {
      ws_->wait(DDS_MSECS(5));
      for (const auto& rx : tools_->take()) {
        if (!rx.valid() || !answering) continue;
        const neurosim_ToolState& ts = rx.data;
        const ContactModelData m =
            tissue_.model_at(Vector3d(ts.position_m[0], ts.position_m[1], ts.position_m[2]),
                             ts.sequence_number, ts.source_time_ns);
        wire::set_string(cm->station_id, wire::get_string(ts.station_id));
        cm->tool_sequence = m.tool_sequence;
        cm->tool_source_time_ns = m.reference_time_ns;
        for (int i = 0; i < 3; ++i) {
          cm->x0_position_m[i] = m.x0_m[i];
          cm->f0_n[i] = m.f0_n[i];
          cm->normal[i] = m.normal[i];
        }
        cm->x0_orientation[0] = 1;
        for (int i = 0; i < 9; ++i) cm->stiffness_n_per_m[i] = m.k_n_per_m(i / 3, i % 3);
        cm->in_contact = m.in_contact;
        cm->validity_radius_m = m.validity_radius_m;
        cm->server_step = ++step;
        models_->write(*cm);
        answered_.fetch_add(1);
      }
      if (std::chrono::steady_clock::now() - last_status > std::chrono::milliseconds(100)) {
        st->steps = step;
        status_->write(*st);
        last_status = std::chrono::steady_clock::now();
      }
    }
  }

  HalfSpace tissue_;
  std::unique_ptr<wire::Participant> pp_;
  std::unique_ptr<wire::Topic<neurosim_ToolState>> tt_;
  std::unique_ptr<wire::Reader<neurosim_ToolState>> tools_;
  std::unique_ptr<wire::Topic<neurosim_ContactModel>> mt_;
  std::unique_ptr<wire::Writer<neurosim_ContactModel>> models_;
  std::unique_ptr<wire::Topic<neurosim_SimStatus>> st_;
  std::unique_ptr<wire::Writer<neurosim_SimStatus>> status_;
  std::unique_ptr<wire::Waitset> ws_;
  std::atomic<bool> stop_{false};
  std::atomic<std::uint64_t> answered_{0};
  std::thread thread_;
};

}  // namespace neurosim::haptic::testing
