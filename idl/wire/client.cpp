#include "idl/wire/client.hpp"

namespace neurosim::wire {

namespace {
ParticipantOptions participant_options(const ClientOptions& o) {
  ParticipantOptions po;
  if (o.domain >= 0) po.domain = static_cast<dds_domainid_t>(o.domain);
  return po;
}
}  // namespace

ClientSession::ClientSession(const ClientOptions& o)
    : pp_(participant_options(o)),
      prefix_(o.topic_prefix),
      status_topic_(pp_, topic_name<neurosim_SimStatus>(prefix_)),
      status_(pp_, status_topic_),
      ws_(pp_) {
  ws_.attach_data(status_, kStatusData);
  ws_.attach_liveliness(status_, kStatusLiveliness);
}

}  // namespace neurosim::wire
