/* Hostile participant for service_fault_test: writes ToolState samples whose station id is LEN
 * bytes (10 kB) under the real topic and type name, with the type's ids unbounded
 * (long_id_tool_state.idl), at 1 kHz for SECONDS, in the partition of a station "x".
 *
 *   service_test_long_id_attacker DOMAIN LEN SECONDS
 *
 * Prints whether it discovered the server's ToolState reader (DCPSSubscription, same topic name)
 * and how many readers its writer matched, then how many samples it wrote. Exit 0 when it ran. */
#include "long_id_tool_state.h"

#include <dds/dds.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static int server_reader_seen(dds_entity_t pp) {
  const dds_entity_t rd = dds_create_reader(pp, DDS_BUILTIN_TOPIC_DCPSSUBSCRIPTION, NULL, NULL);
  void* samples[16] = {NULL};
  dds_sample_info_t infos[16];
  int seen = 0;
  const int n = dds_read(rd, samples, infos, 16, 16);
  for (int i = 0; i < n; ++i) {
    const dds_builtintopic_endpoint_t* e = (const dds_builtintopic_endpoint_t*)samples[i];
    if (infos[i].valid_data && strcmp(e->topic_name, "neurosim_ToolState") == 0 &&
        strcmp(e->type_name, "neurosim::ToolState") == 0)
      seen = 1;
  }
  if (n > 0) dds_return_loan(rd, samples, n);
  dds_delete(rd);
  return seen;
}

int main(int argc, char** argv) {
  if (argc != 4) {
    fprintf(stderr, "usage: %s DOMAIN LEN SECONDS\n", argv[0]);
    return 2;
  }
  const dds_domainid_t domain = (dds_domainid_t)atoi(argv[1]);
  const size_t len = (size_t)atol(argv[2]);
  const double seconds = atof(argv[3]);
  const dds_entity_t pp = dds_create_participant(domain, NULL, NULL);
  if (pp < 0) {
    fprintf(stderr, "participant: %s\n", dds_strretcode(pp));
    return 1;
  }
  dds_qos_t* q = dds_create_qos();
  dds_qset_reliability(q, DDS_RELIABILITY_BEST_EFFORT, 0);
  dds_qset_history(q, DDS_HISTORY_KEEP_LAST, 1);
  const dds_entity_t tp = dds_create_topic(pp, &neurosim_ToolState_desc, "neurosim_ToolState", q, NULL);
  dds_qos_t* pq = dds_create_qos();
  const char* parts[] = {"neurosim.station.x"};
  dds_qset_partition(pq, 1, parts);
  const dds_entity_t pub = dds_create_publisher(pp, pq, NULL);
  const dds_entity_t w = dds_create_writer(pub, tp, q, NULL);
  dds_delete_qos(pq);
  dds_delete_qos(q);
  if (tp < 0 || w < 0) {
    fprintf(stderr, "topic/writer: %s\n", dds_strretcode(tp < 0 ? tp : w));
    return 1;
  }
  int seen = 0;
  for (int i = 0; i < 100 && !seen; ++i) {  /* discovery: up to 5 s */
    seen = server_reader_seen(pp);
    dds_sleepfor(DDS_MSECS(50));
  }
  dds_sleepfor(DDS_MSECS(500)); /* time to match, were the types assignable */
  dds_publication_matched_status_t m;
  dds_get_publication_matched_status(w, &m);
  printf("server ToolState reader discovered: %s; readers matched: %u\n", seen ? "yes" : "no",
         m.current_count);
  fflush(stdout);

  char* id = malloc(len + 1);
  memset(id, 'x', len);
  id[len] = '\0';
  neurosim_ToolState s;
  memset(&s, 0, sizeof s);
  s.station_id = id;
  s.tool_id = "probe";
  s.orientation[0] = 1.0;
  const long total = (long)(seconds * 1000.0);
  long written = 0;
  for (long i = 0; i < total; ++i) {
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    s.sequence_number = (unsigned long long)i + 1;
    s.source_time_ns = (long long)ts.tv_sec * 1000000000LL + ts.tv_nsec;
    if (dds_write(w, &s) == DDS_RETCODE_OK) ++written;
    dds_sleepfor(DDS_MSECS(1));
  }
  printf("wrote %ld of %ld samples with a %zu-byte station id\n", written, total, len);
  free(id);
  dds_delete(pp);
  return 0;
}
