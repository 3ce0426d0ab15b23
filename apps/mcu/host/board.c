/* herm-mcu-board: the C client (hermc) on a host, as a board would run it,
 * on a serial line (a tty or one end of a pseudo-terminal cable). It is the
 * same main loop the firmware runs (docs/mcu.md, "Porting"): bytes from the
 * line go to hermc_feed, hermc_poll_tx's bytes go to the line, and
 * hermc_tick gets a millisecond clock. Tests run it against a real hermd to
 * check the client interoperates with the C++ stack (tests/mcu).
 *
 *   herm-mcu-board --device /dev/pts/5 [--baud 19200] [--id 0x0A04]
 *                  [--echo NAME] [--publish TOPIC --period-ms N]
 *                  [--send APO --period-ms N] [--count N] [--max-seconds S]
 *
 *   --echo NAME      serves APO NAME (type "echo"): a request of one string
 *                    is answered with "echo:" and the string (as
 *                    herm-apo-peer's `call` expects).
 *   --publish TOPIC  publishes a counter (one `@i32` element) every period.
 *   --send APO       sends an SRF04-style reading (`herm::hermd::srf04_reading`,
 *                    seq, distance_mm, echo_us) every period to remote APO
 *                    APO, as a request that waits for its response.
 *   --count N        stops after N publications or readings (0: never).
 *
 * Prints one flushed line per event: "ready ID", "neighbour MID",
 * "served N", "published N subscribers S", "sent N", "response N ok",
 * "response N error CODE", "response N timeout", "not ready N", "counters
 * ...". Exit status: 0 done (count reached, or SIGTERM/SIGINT), 1 the line
 * failed, 2 bad arguments. */
#define _DEFAULT_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include "hermc.h"
#include "hermc_payload.h"

static volatile sig_atomic_t stop_requested = 0;

static void on_signal(int sig) {
  (void)sig;
  stop_requested = 1;
}

static uint32_t now_ms(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (uint32_t)((uint64_t)ts.tv_sec * 1000u
                    + (uint64_t)ts.tv_nsec / 1000000u);
}

static speed_t baud_constant(unsigned long baud) {
  switch (baud) {
    case 9600: return B9600;
    case 19200: return B19200;
    case 38400: return B38400;
    case 57600: return B57600;
    case 115200: return B115200;
    default: return 0;
  }
}

/* Opens the line raw (8N1, no echo, no flow control), non-blocking. */
static int open_line(const char *path, unsigned long baud) {
  int fd = open(path, O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) {
    printf("error cannot open %s: %s\n", path, strerror(errno));
    return -1;
  }
  struct termios t;
  if (tcgetattr(fd, &t) != 0) {
    printf("error %s is not a serial line: %s\n", path, strerror(errno));
    close(fd);
    return -1;
  }
  cfmakeraw(&t);
  t.c_cflag |= CLOCAL | CREAD;
  t.c_cflag &= (tcflag_t)~CRTSCTS;
  cfsetispeed(&t, baud_constant(baud));
  cfsetospeed(&t, baud_constant(baud));
  if (tcsetattr(fd, TCSANOW, &t) != 0) {
    printf("error cannot configure %s: %s\n", path, strerror(errno));
    close(fd);
    return -1;
  }
  return fd;
}

/* -- the APOs ------------------------------------------------------------ */

static unsigned long served = 0;

/* The echo APO, as herm-apo-peer's `call` expects it: a request of one
 * string (`@str`) is answered with "echo:" and that string; anything else
 * is a typed error (herm::ec::invalid_parameter). */
static uint8_t echo_handler(void *ctx, const uint8_t *req, size_t req_len,
                            uint8_t *resp, size_t resp_cap,
                            size_t *resp_len) {
  (void)ctx;
  struct hermc_pr r;
  const uint8_t *text = NULL;
  size_t n = 0;
  if (hermc_pr_begin(&r, req, req_len) != 1u || !hermc_pr_element(&r, "@str"))
    return 4;
  hermc_pr_bytes(&r, &text, &n);
  uint8_t echoed[256];
  if (hermc_pr_finish(&r) != HERMC_PR_OK || n > sizeof echoed - 5)
    return 4;
  memcpy(echoed, "echo:", 5);
  memcpy(echoed + 5, text, n);
  struct hermc_pw w;
  hermc_pw_begin(&w, resp, resp_cap, 1);
  hermc_pw_element(&w, "@str");
  hermc_pw_bytes(&w, echoed, n + 5);
  *resp_len = hermc_pw_finish(&w);
  if (*resp_len == 0)
    return 4; /* does not fit one packet */
  printf("served %lu\n", ++served);
  fflush(stdout);
  return 0;
}

static void on_response(void *ctx, enum hermc_status status,
                        const uint8_t *payload, size_t len,
                        uint64_t err_category, uint8_t err_code) {
  unsigned long n = (unsigned long)(uintptr_t)ctx;
  (void)payload;
  (void)len;
  (void)err_category;
  if (status == HERMC_STATUS_OK)
    printf("response %lu ok\n", n);
  else if (status == HERMC_STATUS_ERROR)
    printf("response %lu error %u\n", n, (unsigned)err_code);
  else
    printf("response %lu timeout\n", n);
  fflush(stdout);
}

static void print_counters(const struct hermc_module *m) {
  const struct hermc_counters *c = &m->counters;
  printf("counters rx_packets %lu rx_malformed %lu rx_asl_malformed %lu "
         "served %lu queries %lu responses %lu timeouts %lu refused %lu "
         "published %lu tx_packets %lu tx_dropped %lu hellos %lu "
         "neighbour_changes %lu\n",
         (unsigned long)c->rx_packets, (unsigned long)c->rx_malformed,
         (unsigned long)c->rx_asl_malformed,
         (unsigned long)c->requests_served,
         (unsigned long)c->queries_answered,
         (unsigned long)c->responses_received,
         (unsigned long)c->request_timeouts,
         (unsigned long)c->requests_refused,
         (unsigned long)c->publications_sent,
         (unsigned long)c->tx_packets, (unsigned long)c->tx_dropped,
         (unsigned long)c->tx_hellos,
         (unsigned long)c->neighbour_changes);
  fflush(stdout);
}

static int usage(const char *why) {
  printf("error %s\n", why);
  fprintf(stderr,
          "usage: herm-mcu-board --device PATH [--baud N] [--id ID] "
          "[--echo NAME] [--publish TOPIC] [--send APO] [--period-ms N] "
          "[--count N] [--max-seconds S]\n");
  return 2;
}

static int parse_ulong(const char *s, unsigned long max, unsigned long *out) {
  char *end = NULL;
  errno = 0;
  unsigned long v = strtoul(s, &end, 0);
  if (errno != 0 || end == s || *end != '\0' || v > max)
    return 0;
  *out = v;
  return 1;
}

static struct hermc_module module;

/* --publish: the counter as one `@i32` element (what herm-apo-peer's
 * subscriber prints). */
static void publish_counter(int t, unsigned long n) {
  uint8_t payload[16];
  struct hermc_pw w;
  hermc_pw_begin(&w, payload, sizeof payload, 1);
  hermc_pw_element(&w, "@i32");
  hermc_pw_u32(&w, (uint32_t)n);
  int sent = hermc_publish(&module, t, payload, hermc_pw_finish(&w));
  if (sent >= 0)
    printf("published %lu subscribers %d\n", n, sent);
  else
    printf("not published %lu: %d\n", n, sent);
}

/* --send: reading n, a request that waits for its response. */
static void send_reading(int r, unsigned long n) {
  if (!hermc_remote_ready(&module, r)) {
    printf("not ready %lu\n", n);
    return;
  }
  uint8_t payload[48];
  uint16_t mm = (uint16_t)(500 + (n * 37) % 3000);
  struct hermc_srf04_reading x = {(uint16_t)n, mm, (uint32_t)mm * 2000u / 343u};
  size_t len = hermc_srf04_encode(&x, payload, sizeof payload);
  int rc = hermc_request(&module, r, payload, len, on_response,
                         (void *)(uintptr_t)n, 0);
  if (rc == HERMC_OK)
    printf("sent %lu\n", n);
  else
    printf("not sent %lu: %d\n", n, rc);
}

int main(int argc, char **argv) {
  const char *device = NULL, *echo = NULL, *topic = NULL, *send_to = NULL;
  unsigned long baud = 19200, id = 0x0A04, period_ms = 1000, count = 0;
  unsigned long max_seconds = 0;
  for (int i = 1; i < argc; ++i) {
    const char *a = argv[i];
    const char *v = i + 1 < argc ? argv[i + 1] : NULL;
    if (v == NULL)
      return usage("an option needs a value");
    ++i;
    if (strcmp(a, "--device") == 0)
      device = v;
    else if (strcmp(a, "--echo") == 0)
      echo = v;
    else if (strcmp(a, "--publish") == 0)
      topic = v;
    else if (strcmp(a, "--send") == 0)
      send_to = v;
    else if (strcmp(a, "--baud") == 0) {
      if (!parse_ulong(v, 115200, &baud) || baud_constant(baud) == 0)
        return usage("--baud: 9600, 19200, 38400, 57600 or 115200");
    } else if (strcmp(a, "--id") == 0) {
      if (!parse_ulong(v, 0xFFFE, &id) || id == 0)
        return usage("--id: 1 .. 0xFFFE");
    } else if (strcmp(a, "--period-ms") == 0) {
      if (!parse_ulong(v, 3600000, &period_ms) || period_ms == 0)
        return usage("--period-ms: 1 .. 3600000");
    } else if (strcmp(a, "--count") == 0) {
      if (!parse_ulong(v, 1000000000, &count))
        return usage("--count: a number");
    } else if (strcmp(a, "--max-seconds") == 0) {
      if (!parse_ulong(v, 86400, &max_seconds))
        return usage("--max-seconds: a number");
    } else {
      return usage("unknown option");
    }
  }
  if (device == NULL)
    return usage("--device is required");
  setvbuf(stdout, NULL, _IOLBF, 0);
  signal(SIGTERM, on_signal);
  signal(SIGINT, on_signal);
  signal(SIGPIPE, SIG_IGN);
  int fd = open_line(device, baud);
  if (fd < 0)
    return 1;

  /* A host has a clock that differs from boot to boot: the instance. */
  struct timespec rt;
  clock_gettime(CLOCK_REALTIME, &rt);
  uint64_t instance = ((uint64_t)rt.tv_sec << 20) ^ (uint64_t)rt.tv_nsec
                      ^ ((uint64_t)getpid() << 40);
  if (instance == 0)
    instance = 1;
  struct hermc_config cfg;
  hermc_config_default(&cfg, (uint16_t)id, instance);
  if (hermc_init(&module, &cfg) != HERMC_OK) {
    close(fd);
    return usage("the module's configuration is refused");
  }
  if (echo != NULL && hermc_register_apo(&module, echo, "echo", echo_handler,
                                         NULL) < 0) {
    close(fd);
    return usage("--echo: the APO cannot be registered");
  }
  int t = topic != NULL ? hermc_topic(&module, topic) : -1;
  int r = send_to != NULL ? hermc_remote(&module, send_to) : -1;
  printf("ready 0x%04lX\n", id);

  uint32_t start = now_ms();
  uint32_t next_period = start + (uint32_t)period_ms;
  unsigned long done = 0;
  uint16_t neighbour = 0;
  uint8_t out[256];
  uint8_t in[256];
  int status = 0;
  while (!stop_requested) {
    struct pollfd p = {fd, POLLIN, 0};
    if (hermc_link_tx_pending(&module.tx) > 0)
      p.events |= POLLOUT;
    int n = poll(&p, 1, 10);
    if (n < 0 && errno != EINTR) {
      printf("error poll: %s\n", strerror(errno));
      status = 1;
      break;
    }
    if (n > 0 && (p.revents & POLLIN)) {
      ssize_t got = read(fd, in, sizeof in);
      if (got > 0)
        hermc_feed(&module, in, (size_t)got);
      else if (got < 0 && errno != EAGAIN && errno != EINTR) {
        printf("error the line failed: %s\n", strerror(errno));
        status = 1;
        break;
      }
    }
    uint32_t now = now_ms();
    hermc_tick(&module, now);
    if (module.neighbour != neighbour) {
      neighbour = module.neighbour;
      printf("neighbour 0x%04X\n", (unsigned)neighbour);
    }
    if ((int32_t)(now - next_period) >= 0 && (t >= 0 || r >= 0)
        && (count == 0 || done < count)) {
      next_period += (uint32_t)period_ms;
      ++done;
      if (t >= 0)
        publish_counter(t, done);
      if (r >= 0)
        send_reading(r, done);
    }
    size_t k;
    while ((k = hermc_poll_tx(&module, out, sizeof out)) > 0) {
      size_t off = 0;
      while (off < k) {
        ssize_t w = write(fd, out + off, k - off);
        if (w > 0) {
          off += (size_t)w;
        } else if (w < 0 && (errno == EAGAIN || errno == EINTR)) {
          struct pollfd q = {fd, POLLOUT, 0};
          poll(&q, 1, 10);
        } else {
          printf("error the line failed: %s\n", strerror(errno));
          status = 1;
          goto out;
        }
      }
    }
    if (count != 0 && done >= count && hermc_link_tx_pending(&module.tx) == 0
        && r < 0)
      break; /* (with --send: runs on for the responses, until --max-seconds) */
    if (max_seconds != 0 && now - start >= max_seconds * 1000u)
      break;
  }
out:
  print_counters(&module);
  close(fd);
  return status;
}
