/* A ROS 2 node's view of a HERM robot, with nothing of HERM in it: Cyclone
 * DDS's C API and the types idlc generated from apps/dds_gateway/idl.
 *
 *   dds_peer DOMAIN RANGES TWISTS BAD TIMEOUT_MS [CALLS [IMAGES]]
 *
 * On domain DOMAIN it subscribes to rt/sonar as
 * sensor_msgs::msg::dds_::Range_ and prints each reading,
 *   range <metres> frame <frame_id> radiation <type> fov <rad>
 * plus once the encoding of the first sample as it came off the wire,
 *   encoding <byte 0> <byte 1>   (00 01: XCDR1 little-endian, CDR_LE)
 * until RANGES readings came. Once a reader matches its writer it publishes
 * TWISTS geometry_msgs::msg::dds_::Twist_ on rt/cmd_vel (linear.x = 0.1 i,
 * angular.z = -i) and BAD Range_ samples whose range is NaN on
 * rt/sonar_in, printing "sent twists" and "sent bad".
 *
 * With CALLS, it is also a ROS 2 service client and server as
 * rmw_cyclonedds lays them out (rq/<S>Request, rr/<S>Reply, the request
 * header {guid, seq} first):
 *  - it calls example_interfaces/srv/AddTwoInts "add_two_ints" CALLS times
 *    (a = k, b = 10 k for k = 1..CALLS) and prints each reply with its own
 *    guid, "sum <seq> <sum>";
 *  - it serves "dds_adder" (sum = a + b, header repeated), printing
 *    "served <a> <b>";
 *  - it takes requests of "dds_silent" and never answers them, printing
 *    "ignored <a> <b>".
 * It then also waits for all CALLS replies, one dds_adder and one
 * dds_silent request.
 *
 * With IMAGES, it also subscribes to rt/vision as
 * sensor_msgs::msg::dds_::Image_ and prints each image,
 *   image <width>x<height> <encoding> frame <frame_id> bytes <n> first <byte>
 * until IMAGES images came.
 *
 * Exits 0 when everything came and was sent, 1 when TIMEOUT_MS passed
 * first, 2 on a usage or DDS error. Restrict it to loopback with
 * CYCLONEDDS_URI. */

#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "dds/dds.h"
#include "dds/ddsi/ddsi_serdata.h"

#include "example_interfaces/AddTwoInts.h"
#include "geometry_msgs/Twist.h"
#include "sensor_msgs/Image.h"
#include "sensor_msgs/Range.h"

static dds_entity_t check(dds_entity_t e, const char* what) {
  if (e < 0) {
    printf("error %s: %s\n", what, dds_strretcode(e));
    fflush(stdout);
    exit(2);
  }
  return e;
}

static int matched(dds_entity_t writer) {
  dds_publication_matched_status_t st;
  return dds_get_publication_matched_status(writer, &st) == 0
         && st.current_count > 0;
}

static int sub_matched(dds_entity_t reader) {
  dds_subscription_matched_status_t st;
  return dds_get_subscription_matched_status(reader, &st) == 0
         && st.current_count > 0;
}

int main(int argc, char** argv) {
  if (argc < 6 || argc > 8) {
    fprintf(stderr, "usage: dds_peer DOMAIN RANGES TWISTS BAD TIMEOUT_MS "
                    "[CALLS [IMAGES]]\n");
    return 2;
  }
  int calls = argc >= 7 ? atoi(argv[6]) : 0;
  int want_images = argc == 8 ? atoi(argv[7]) : 0;
  dds_domainid_t domain = (dds_domainid_t) atoi(argv[1]);
  int want_ranges = atoi(argv[2]);
  int twists = atoi(argv[3]);
  int bad = atoi(argv[4]);
  dds_time_t deadline = dds_time() + DDS_MSECS(atoll(argv[5]));

  dds_entity_t pp = check(dds_create_participant(domain, NULL, NULL),
                          "participant");
  /* ROS 2's default QoS: reliable, keep_last 10, volatile. */
  dds_qos_t* qos = dds_create_qos();
  dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_MSECS(100));
  dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, 10);
  dds_entity_t sonar = check(
    dds_create_topic(pp, &sensor_msgs_msg_dds__Range__desc, "rt/sonar", NULL,
                     NULL),
    "topic rt/sonar");
  dds_entity_t reader = check(dds_create_reader(pp, sonar, qos, NULL),
                              "reader rt/sonar");
  dds_entity_t raw = check(dds_create_reader(pp, sonar, qos, NULL),
                           "raw reader rt/sonar");
  dds_entity_t vision = 0;
  if (want_images > 0)
    vision = check(
      dds_create_reader(pp, check(dds_create_topic(pp,
                                                   &sensor_msgs_msg_dds__Image__desc,
                                                   "rt/vision", NULL, NULL),
                                  "topic rt/vision"),
                        qos, NULL),
      "reader rt/vision");
  dds_entity_t cmd = check(
    dds_create_topic(pp, &geometry_msgs_msg_dds__Twist__desc, "rt/cmd_vel",
                     NULL, NULL),
    "topic rt/cmd_vel");
  dds_entity_t cmd_writer = check(dds_create_writer(pp, cmd, qos, NULL),
                                  "writer rt/cmd_vel");
  dds_entity_t sonar_in = check(
    dds_create_topic(pp, &sensor_msgs_msg_dds__Range__desc, "rt/sonar_in",
                     NULL, NULL),
    "topic rt/sonar_in");
  dds_entity_t bad_writer = check(dds_create_writer(pp, sonar_in, qos, NULL),
                                  "writer rt/sonar_in");
  /* Services: a client of add_two_ints, the server of dds_adder, a
   * silent server of dds_silent. */
  const dds_topic_descriptor_t* rq_desc
    = &example_interfaces_srv_dds__AddTwoInts_Request__desc;
  const dds_topic_descriptor_t* rr_desc
    = &example_interfaces_srv_dds__AddTwoInts_Response__desc;
  dds_entity_t call_writer = 0, reply_reader = 0, adder_reader = 0,
               adder_writer = 0, silent_reader = 0;
  if (calls > 0) {
    call_writer = check(
      dds_create_writer(pp, check(dds_create_topic(pp, rq_desc,
                                                   "rq/add_two_intsRequest",
                                                   NULL, NULL),
                                  "topic rq/add_two_intsRequest"),
                        qos, NULL),
      "writer rq/add_two_intsRequest");
    reply_reader = check(
      dds_create_reader(pp, check(dds_create_topic(pp, rr_desc,
                                                   "rr/add_two_intsReply",
                                                   NULL, NULL),
                                  "topic rr/add_two_intsReply"),
                        qos, NULL),
      "reader rr/add_two_intsReply");
    adder_reader = check(
      dds_create_reader(pp, check(dds_create_topic(pp, rq_desc,
                                                   "rq/dds_adderRequest",
                                                   NULL, NULL),
                                  "topic rq/dds_adderRequest"),
                        qos, NULL),
      "reader rq/dds_adderRequest");
    adder_writer = check(
      dds_create_writer(pp, check(dds_create_topic(pp, rr_desc,
                                                   "rr/dds_adderReply", NULL,
                                                   NULL),
                                  "topic rr/dds_adderReply"),
                        qos, NULL),
      "writer rr/dds_adderReply");
    silent_reader = check(
      dds_create_reader(pp, check(dds_create_topic(pp, rq_desc,
                                                   "rq/dds_silentRequest",
                                                   NULL, NULL),
                                  "topic rq/dds_silentRequest"),
                        qos, NULL),
      "reader rq/dds_silentRequest");
  }
  dds_instance_handle_t my_guid = 0;
  if (calls > 0)
    dds_get_instance_handle(call_writer, &my_guid);
  dds_delete_qos(qos);

  dds_entity_t ws = check(dds_create_waitset(pp), "waitset");
  dds_entity_t rc = check(dds_create_readcondition(reader, DDS_ANY_STATE),
                          "read condition");
  check(dds_waitset_attach(ws, rc, 0), "attach");
  printf("ready\n");
  fflush(stdout);

  int ranges = 0, sent_twists = 0, sent_bad = 0, encoding_shown = 0;
  int sent_calls = 0, replies = 0, served = 0, ignored = 0, images = 0;
  dds_time_t next_send = 0;
  while (dds_time() < deadline) {
    if (ranges >= want_ranges && sent_twists >= twists && sent_bad >= bad
        && replies >= calls && (calls == 0 || (served > 0 && ignored > 0))
        && images >= want_images)
      break;
    /* Send one of each due every 50 ms once the other side listens. */
    if (dds_time() >= next_send) {
      next_send = dds_time() + DDS_MSECS(50);
      if (sent_twists < twists && matched(cmd_writer)) {
        geometry_msgs_msg_dds__Twist_ t = {{0.1 * sent_twists, 0, 0},
                                           {0, 0, -sent_twists}};
        if (dds_write(cmd_writer, &t) == 0 && ++sent_twists == twists) {
          printf("sent twists %d\n", sent_twists);
          fflush(stdout);
        }
      }
      /* Both ways matched: a reply has a reader to go to. */
      if (sent_calls < calls && matched(call_writer)
          && sub_matched(reply_reader)) {
        example_interfaces_srv_dds__AddTwoInts_Request_ rq
          = {{my_guid, sent_calls + 1}, sent_calls + 1, 10 * (sent_calls + 1)};
        if (dds_write(call_writer, &rq) == 0)
          ++sent_calls;
      }
      if (sent_bad < bad && matched(bad_writer)) {
        sensor_msgs_msg_dds__Range_ r = {{{0, 0}, "bad"}, 0, 0.5f, 0.0f, 1.0f,
                                          NAN};
        if (dds_write(bad_writer, &r) == 0 && ++sent_bad == bad) {
          printf("sent bad %d\n", sent_bad);
          fflush(stdout);
        }
      }
    }
    dds_waitset_wait(ws, NULL, 0, DDS_MSECS(20));
    void* samples[8] = {NULL};
    dds_sample_info_t infos[8];
    int n = dds_take(reader, samples, infos, 8, 8);
    for (int i = 0; i < n; ++i) {
      if (!infos[i].valid_data)
        continue;
      sensor_msgs_msg_dds__Range_* r = samples[i];
      printf("range %.3f frame %s radiation %u fov %.2f\n", r->range,
             r->header.frame_id, r->radiation_type, r->field_of_view);
      ++ranges;
    }
    if (n > 0)
      dds_return_loan(reader, samples, n);
    if (want_images > 0) {
      void* s[4] = {NULL};
      dds_sample_info_t si[4];
      int k = dds_take(vision, s, si, 4, 4);
      for (int i = 0; i < k; ++i) {
        sensor_msgs_msg_dds__Image_* im = s[i];
        if (!si[i].valid_data)
          continue;
        printf("image %ux%u %s frame %s bytes %u first %u\n", im->width,
               im->height, im->encoding, im->header.frame_id,
               im->data._length,
               im->data._length > 0 ? im->data._buffer[0] : 0u);
        ++images;
      }
      if (k > 0)
        dds_return_loan(vision, s, k);
    }
    struct ddsi_serdata* cdr[8];
    dds_sample_info_t raw_infos[8];
    int m = dds_takecdr(raw, cdr, 8, raw_infos, DDS_ANY_STATE);
    for (int i = 0; i < m; ++i) {
      if (raw_infos[i].valid_data && !encoding_shown) {
        unsigned char hdr[4];
        ddsi_serdata_to_ser(cdr[i], 0, sizeof hdr, hdr);
        printf("encoding %02x %02x\n", hdr[0], hdr[1]);
        encoding_shown = 1;
      }
      ddsi_serdata_unref(cdr[i]);
    }
    if (calls > 0) {
      void* s[4] = {NULL};
      dds_sample_info_t si[4];
      int k = dds_take(reply_reader, s, si, 4, 4);
      for (int i = 0; i < k; ++i) {
        example_interfaces_srv_dds__AddTwoInts_Response_* r = s[i];
        if (si[i].valid_data && r->header.guid == my_guid) {
          printf("sum %lld %lld\n", (long long) r->header.seq,
                 (long long) r->sum);
          ++replies;
        }
      }
      if (k > 0)
        dds_return_loan(reply_reader, s, k);
      s[0] = NULL;
      k = dds_take(adder_reader, s, si, 4, 4);
      for (int i = 0; i < k; ++i) {
        example_interfaces_srv_dds__AddTwoInts_Request_* q = s[i];
        if (!si[i].valid_data)
          continue;
        example_interfaces_srv_dds__AddTwoInts_Response_ r
          = {q->header, q->a + q->b};
        if (dds_write(adder_writer, &r) == 0) {
          printf("served %lld %lld\n", (long long) q->a, (long long) q->b);
          ++served;
        }
      }
      if (k > 0)
        dds_return_loan(adder_reader, s, k);
      s[0] = NULL;
      k = dds_take(silent_reader, s, si, 4, 4);
      for (int i = 0; i < k; ++i) {
        example_interfaces_srv_dds__AddTwoInts_Request_* q = s[i];
        if (si[i].valid_data) {
          printf("ignored %lld %lld\n", (long long) q->a, (long long) q->b);
          ++ignored;
        }
      }
      if (k > 0)
        dds_return_loan(silent_reader, s, k);
    }
    fflush(stdout);
  }
  int ok = ranges >= want_ranges && sent_twists >= twists && sent_bad >= bad
           && replies >= calls && (calls == 0 || (served > 0 && ignored > 0))
           && images >= want_images;
  printf("done ranges %d twists %d bad %d replies %d served %d ignored %d "
         "images %d\n",
         ranges, sent_twists, sent_bad, replies, served, ignored, images);
  fflush(stdout);
  dds_delete(pp);
  return ok ? 0 : 1;
}
