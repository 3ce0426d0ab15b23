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
 *   --count N        N publications or readings, counted once sent (0: no
 *                    limit; a reading waits until its APO is discovered).
 *                    With --publish it then exits; with --send it stays for
 *                    the responses, until --max-seconds or a signal.
 *
 * Built with HERMC_AUTH=1 (herm-mcu-board-keyed), it joins a keyed network
 * (hermd's `auth` section, docs/user-guide.md) with the same settings:
 *   --key-file PATH  the network's key file, as hermd reads it: 16..64 bytes
 *                    as hex digits on one line, a regular file (not a
 *                    symbolic link) owned by this user, mode 0600 or 0400;
 *                    anything else is refused with the reason (exit 2).
 *   --key-id N       0..255 (default 1);  --tag-bytes 8|16 (default 8);
 *   --auth-data discovery|all (default discovery).
 * Its sender index is drawn from /dev/urandom at start (one per boot).
 * Without --key-file it runs unkeyed.
 *
 * Prints one flushed line per event: "ready ID", "neighbour MID",
 * "served N", "published N subscribers S", "sent N", "response N ok",
 * "response N error CODE", "response N timeout", "not ready N", and at
 * exit "counters ..." and "link ..." (what the line broke). Exit status: 0 done (count reached, or SIGTERM/SIGINT), 1 the line
 * failed, 2 bad arguments. */
#define _DEFAULT_SOURCE
#include <errno.h>
#include <sys/stat.h>
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
    return HERMC_EC_INVALID_PARAMETER;
  hermc_pr_bytes(&r, &text, &n);
  uint8_t echoed[256];
  if (hermc_pr_finish(&r) != HERMC_PR_OK || n > sizeof echoed - 5)
    return HERMC_EC_INVALID_PARAMETER;
  memcpy(echoed, "echo:", 5);
  memcpy(echoed + 5, text, n);
  struct hermc_pw w;
  hermc_pw_begin(&w, resp, resp_cap, 1);
  hermc_pw_element(&w, "@str");
  hermc_pw_bytes(&w, echoed, n + 5);
  *resp_len = hermc_pw_finish(&w);
  if (*resp_len == 0)
    return HERMC_EC_INVALID_PARAMETER; /* does not fit one packet */
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

#if HERMC_AUTH
/* The value of hex digit c, or -1. */
static int hex_value(char c) {
  if (c >= '0' && c <= '9')
    return c - '0';
  if (c >= 'a' && c <= 'f')
    return c - 'a' + 10;
  if (c >= 'A' && c <= 'F')
    return c - 'A' + 10;
  return -1;
}

/* Reads a key file by hermd's rules (routing/auth.cpp read_key) into
 * key[0..64); returns its length, or 0 after printing why it is refused. */
static size_t read_key_file(const char *path, uint8_t key[HERMC_AUTH_KEY_MAX]) {
  char text[1025];
  size_t got = 0, n, i;
  struct stat st;
  int fd = open(path, O_RDONLY | O_NOFOLLOW | O_CLOEXEC | O_NOCTTY | O_NONBLOCK);
  if (fd < 0) {
    printf("error %s: key file %s\n", path,
           errno == ELOOP ? "is a symbolic link (name the file itself)"
                          : strerror(errno));
    return 0;
  }
  const char *why = NULL;
  if (fstat(fd, &st) != 0)
    why = "cannot be examined";
  else if (!S_ISREG(st.st_mode))
    why = "is not a regular file";
  else if (st.st_uid != geteuid())
    why = "is not owned by this user";
  else if ((st.st_mode & 077) != 0)
    why = "may be accessed by group or others (chmod 600)";
  else if (st.st_size > 1024)
    why = "is larger than 1024 bytes";
  while (why == NULL && got < sizeof text - 1) {
    ssize_t r = read(fd, text + got, sizeof text - 1 - got);
    if (r < 0 && errno == EINTR)
      continue;
    if (r <= 0)
      break;
    got += (size_t)r;
  }
  close(fd);
  if (got > 0 && text[got - 1] == '\n')
    --got;
  if (got > 0 && text[got - 1] == '\r')
    --got;
  for (i = 0; why == NULL && i < got; ++i)
    if (hex_value(text[i]) < 0)
      why = "must hold hex digits only";
  n = got / 2;
  if (why == NULL && (got % 2 != 0 || n < HERMC_AUTH_KEY_MIN || n > HERMC_AUTH_KEY_MAX))
    why = "must hold 16 to 64 bytes as an even number of hex digits";
  if (why != NULL) {
    memset(text, 0, sizeof text);
    printf("error %s: key file %s\n", path, why);
    return 0;
  }
  for (i = 0; i < n; ++i)
    key[i] = (uint8_t)(hex_value(text[2 * i]) << 4 | hex_value(text[2 * i + 1]));
  memset(text, 0, sizeof text);
  return n;
}

/* This boot's sender index: random, as the C++ draws it. */
static uint32_t random_index(uint64_t fallback) {
  uint32_t x = (uint32_t)(fallback ^ (fallback >> 32));
  int fd = open("/dev/urandom", O_RDONLY | O_CLOEXEC);
  if (fd >= 0) {
    uint8_t b[4];
    if (read(fd, b, sizeof b) == (ssize_t)sizeof b)
      x = (uint32_t)b[0] | (uint32_t)b[1] << 8 | (uint32_t)b[2] << 16
          | (uint32_t)b[3] << 24;
    close(fd);
  }
  return x;
}
#endif /* HERMC_AUTH */

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
  /* What the line broke: frames (COBS, CRC-16) and packets (reassembly). */
  const hermc_frame_stats *f = &m->rx.frame_stats;
  const hermc_reasm_stats *r = &m->rx.reasm.stats;
  printf("link bad_cobs %lu too_short %lu oversized %lu bad_crc %lu "
         "malformed %lu orphans %lu lost %lu bad_checksum %lu timed_out %lu\n",
         (unsigned long)f->bad_cobs, (unsigned long)f->too_short,
         (unsigned long)f->oversized, (unsigned long)f->bad_crc,
         (unsigned long)r->malformed, (unsigned long)r->orphans,
         (unsigned long)r->lost, (unsigned long)r->bad_checksum,
         (unsigned long)r->timed_out);
#if HERMC_AUTH
  const struct hermc_auth_counters *a = &m->auth.counters;
  printf("auth signed %lu accepted %lu truncated %lu wrong_key_id %lu "
         "bad_tag %lu replayed %lu unsigned %lu challenges_sent %lu "
         "challenges_passed %lu replies %lu\n",
         (unsigned long)a->signed_packets, (unsigned long)a->accepted,
         (unsigned long)a->truncated, (unsigned long)a->wrong_key_id,
         (unsigned long)a->bad_tag, (unsigned long)a->replayed,
         (unsigned long)a->rx_unsigned, (unsigned long)a->challenges_sent,
         (unsigned long)a->challenges_passed, (unsigned long)a->replies);
#endif
  fflush(stdout);
}

static int usage(const char *why) {
  printf("error %s\n", why);
  fprintf(stderr,
          "usage: herm-mcu-board --device PATH [--baud N] [--id ID] "
          "[--echo NAME] [--publish TOPIC] [--send APO] [--period-ms N] "
          "[--count N] [--max-seconds S]%s\n",
          HERMC_AUTH ? " [--key-file PATH] [--key-id N] [--tag-bytes 8|16] "
                       "[--auth-data discovery|all]"
                     : "");
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
static int publish_counter(int t, unsigned long n) {
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
  return sent >= 0;
}

/* --send: reading n, a request that waits for its response. 1 if sent. */
static int send_reading(int r, unsigned long n) {
  if (!hermc_remote_ready(&module, r)) {
    printf("not ready %lu\n", n);
    return 0;
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
  return rc == HERMC_OK;
}

int main(int argc, char **argv) {
  const char *device = NULL, *echo = NULL, *topic = NULL, *send_to = NULL;
  unsigned long baud = 19200, id = 0x0A04, period_ms = 1000, count = 0;
  unsigned long max_seconds = 0;
#if HERMC_AUTH
  const char *key_file = NULL;
  unsigned long key_id = 1, tag_bytes = 8, data_all = 0;
#endif
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
#if HERMC_AUTH
    } else if (strcmp(a, "--key-file") == 0) {
      key_file = v;
    } else if (strcmp(a, "--key-id") == 0) {
      if (!parse_ulong(v, 255, &key_id))
        return usage("--key-id: 0 .. 255");
    } else if (strcmp(a, "--tag-bytes") == 0) {
      if (!parse_ulong(v, 16, &tag_bytes) || (tag_bytes != 8 && tag_bytes != 16))
        return usage("--tag-bytes: 8 or 16");
    } else if (strcmp(a, "--auth-data") == 0) {
      if (strcmp(v, "discovery") != 0 && strcmp(v, "all") != 0)
        return usage("--auth-data: discovery or all");
      data_all = strcmp(v, "all") == 0;
#endif
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
#if HERMC_AUTH
  if (key_file != NULL) {
    uint8_t key[HERMC_AUTH_KEY_MAX];
    size_t key_len = read_key_file(key_file, key);
    int rc = key_len == 0 ? HERMC_ERR_ARG
                          : hermc_set_key(&module, key, key_len, (uint8_t)key_id,
                                          (uint8_t)tag_bytes, (uint8_t)data_all,
                                          random_index(instance));
    memset(key, 0, sizeof key);
    if (rc != HERMC_OK) {
      close(fd);
      return usage("--key-file: the key is refused");
    }
  }
#endif
  if (echo != NULL && hermc_register_apo(&module, echo, "echo", echo_handler,
                                         NULL) < 0) {
    close(fd);
    return usage("--echo: the APO cannot be registered");
  }
  int t = topic != NULL ? hermc_topic(&module, topic) : -1;
  int r = send_to != NULL ? hermc_remote(&module, send_to) : -1;
#if HERMC_AUTH
  printf("ready 0x%04lX%s\n", id, module.keyed ? " keyed" : "");
#else
  printf("ready 0x%04lX\n", id);
#endif

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
      /* A value counts once it went out: a reading waits (the next period
       * tries the same number again) until its APO is discovered. */
      int went = 0;
      if (t >= 0)
        went |= publish_counter(t, done + 1);
      if (r >= 0)
        went |= send_reading(r, done + 1);
      if (went)
        ++done;
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
