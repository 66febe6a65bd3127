/*
 * spiv-core from C: the sidecar loop over the committed spike strip, through
 * the static library of `spiv-ffi` (ffi/include/spiv_core.h).
 *
 * Prints the parity line of `spiv-firmware-sim --checksum` and of the
 * Cortex-M4 firmware (firmware-sim/cortex-m4/expected.txt):
 *
 *   planes=… frames=… messages=… bytes=… stream_crc=… frame_crcs=…,…
 *
 * and, given the host's control message, the motion-compensated run's line
 * after "mc " (expected-mc.txt). Build and run (README, "C ABI"):
 *
 *   cargo build -p spiv-ffi --release
 *   cc -O2 -std=c11 -Wall -Wextra -pedantic -Iffi/include examples/c/parity.c \
 *      target/release/libspiv_ffi.a -lpthread -ldl -lm -o parity
 *   ./parity firmware-sim/cortex-m4/data/strip.dat \
 *      firmware-sim/cortex-m4/data/control.bin
 *
 * The strip is 128 x 64 px of the default paper-linear scene, 144 planes,
 * pairs 13 ticks apart (firmware-sim/cortex-m4/data/scene.json).
 */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>

#include "spiv_core.h"

#define W 128
#define H 64
#define DT 13
#define PLANE_BYTES (W * H / 8)

/* CRC-32 (ISO-HDLC, as zlib) of the message stream: the parity line's. */
static uint32_t crc32_update(uint32_t crc, const uint8_t *p, size_t n) {
  crc = ~crc;
  while (n--) {
    crc ^= *p++;
    for (int k = 0; k < 8; k++) crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
  }
  return ~crc;
}

/* The link: a real sidecar queues the bytes on its USB bulk IN endpoint;
 * here they only go into the running CRC. */
struct tap {
  uint32_t stream_crc;
  uint32_t frame_crcs[2];
};

static int32_t send_message(void *ctx, const uint8_t *bytes, size_t len) {
  struct tap *t = ctx;
  t->stream_crc = crc32_update(t->stream_crc, bytes, len);
  return 0;
}

static void frame_sent(void *ctx, const SpivFrameInfo *info, const void *samples) {
  (void)samples;
  struct tap *t = ctx;
  if (info->member < 2) t->frame_crcs[info->member] = info->crc;
}

static uint8_t *read_file(const char *path, size_t *len) {
  FILE *f = fopen(path, "rb");
  if (!f) return NULL;
  size_t cap = 1 << 16, n = 0;
  uint8_t *buf = malloc(cap);
  size_t got;
  while (buf && (got = fread(buf + n, 1, cap - n, f)) > 0) {
    n += got;
    if (n == cap) {
      uint8_t *more = realloc(buf, cap *= 2);
      if (!more) { free(buf); buf = NULL; }
      buf = more;
    }
  }
  fclose(f);
  *len = n;
  return buf;
}

static int fail(const char *what, SpivStatus s) {
  fprintf(stderr, "parity: %s: %s\n", what, spiv_status_message(s));
  return 1;
}

/* One run of the loop over the strip; prints its parity line. */
static int run(const uint8_t *strip, size_t strip_len, const SpivConfig *cfg,
               const uint8_t *control, size_t control_len, const char *prefix) {
  size_t need = 0;
  SpivStatus s = spiv_memory_size(cfg, &need);
  if (s != SPIV_OK) return fail("memory size", s);
  /* On a device this block is a static array; malloc is 8-byte aligned. */
  void *mem = malloc(need);
  if (!mem) return fail("memory", SPIV_ERR_MEMORY);
  SpivSidecar *sc = NULL;
  s = spiv_init(cfg, mem, need, &sc);
  if (s != SPIV_OK) { free(mem); return fail("init", s); }
  if (control) {
    s = spiv_hear(sc, control, control_len);
    uint32_t heard = 0, refused = 0;
    spiv_downlink(sc, &heard, NULL, &refused);
    if (s != SPIV_OK || heard != 1 || refused != 0) {
      free(mem);
      fprintf(stderr, "parity: the control was not heard\n");
      return 1;
    }
  }
  struct tap tap = {0, {0, 0}};
  SpivLink link = {send_message, frame_sent, &tap};
  for (size_t off = 0; off + PLANE_BYTES <= strip_len; off += PLANE_BYTES) {
    if (spiv_done(sc)) break;
    s = spiv_push_plane(sc, strip + off, PLANE_BYTES, &link);
    if (s != SPIV_OK) { free(mem); return fail("push plane", s); }
  }
  SpivSent sent;
  s = spiv_finish(sc, &link, &sent);
  free(mem);
  if (s != SPIV_OK) return fail("finish", s);
  printf("%splanes=%u frames=%u messages=%u bytes=%llu stream_crc=%08x frame_crcs=%08x,%08x\n",
         prefix, (unsigned)sent.planes, (unsigned)sent.frames, (unsigned)sent.messages,
         (unsigned long long)sent.bytes, (unsigned)tap.stream_crc, (unsigned)tap.frame_crcs[0],
         (unsigned)tap.frame_crcs[1]);
  return 0;
}

int main(int argc, char **argv) {
  if (argc < 2 || argc > 3) {
    fprintf(stderr, "usage: parity STRIP.dat [CONTROL.bin]\n");
    return 2;
  }
  size_t strip_len = 0, control_len = 0;
  uint8_t *strip = read_file(argv[1], &strip_len);
  if (!strip) { fprintf(stderr, "parity: cannot read %s\n", argv[1]); return 1; }

  /* spiv-firmware-sim's defaults: adaptive, first frame at n_max/2, one pair. */
  SpivConfig cfg;
  spiv_config_default(W, H, DT, &cfg);
  cfg.pairs = 1;
  int rc = run(strip, strip_len, &cfg, NULL, 0, "");

  if (rc == 0 && argc == 3) {
    uint8_t *control = read_file(argv[2], &control_len);
    if (!control) { fprintf(stderr, "parity: cannot read %s\n", argv[2]); free(strip); return 1; }
    /* spiv-firmware-sim --method mc: refine on; the control applies from
     * the first frame, so no bootstrap frame is made. */
    SpivConfig mc = cfg;
    mc.method = SPIV_METHOD_MC;
    mc.bootstrap = SPIV_METHOD_ADAPTIVE;
    mc.refine = 1;
    rc = run(strip, strip_len, &mc, control, control_len, "mc ");
    free(control);
  }
  free(strip);
  return rc;
}
