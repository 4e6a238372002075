/* Standalone test of the version-1 codec. Built by tests/test_protocol_c.py
 * with -Wall -Wextra -Werror under AddressSanitizer and UBSan; buffers
 * given to the codec are heap blocks of the exact size, so a byte written
 * or read past them stops the test. Fixed seed, many random cases. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "mar_cobs.h"
#include "mar_crc.h"
#include "mar_deframer.h"
#include "mar_fuzz.h"
#include "mar_proto.h"
#include "mar_proto_can.h"

static int failures;
#define CHECK(cond, ...)                                               \
    do {                                                               \
        if (!(cond)) {                                                 \
            if (++failures < 50) {                                     \
                fprintf(stderr, "FAIL %s:%d: ", __FILE__, __LINE__);   \
                fprintf(stderr, __VA_ARGS__);                          \
                fputc('\n', stderr);                                   \
            }                                                          \
        }                                                              \
    } while (0)

static uint64_t rng = 20261122u;
static uint32_t below(uint32_t n) { return (uint32_t)((mar_fuzz_next(&rng) >> 32) % n); }

static void test_crc(void)
{
    const uint8_t check[] = "123456789";
    CHECK(mar_crc32c(check, 9) == MAR_CRC32C_CHECK, "check value %08x", (unsigned)mar_crc32c(check, 9));
    CHECK(mar_crc32c(NULL, 0) == 0, "empty");
    uint8_t buf[300];
    for (int round = 0; round < 200; round++) {
        size_t n = below(sizeof buf), k = n ? below((uint32_t)n + 1) : 0;
        for (size_t i = 0; i < n; i++)
            buf[i] = (uint8_t)below(256);
        CHECK(mar_crc32c_update(mar_crc32c_update(0, buf, k), buf + k, n - k) == mar_crc32c(buf, n),
              "incremental CRC, %zu + %zu bytes", k, n - k);
    }
}

static void test_cobs(void)
{
    for (int round = 0; round < 3000; round++) {
        size_t n = round < 1100 ? (size_t)round : below(2000);
        int zeros = below(4);           /* none, few, many, all */
        uint8_t *in = malloc(n + 1), *out = malloc(MAR_COBS_MAX(n)), *back = malloc(n + 1);
        for (size_t i = 0; i < n; i++) {
            uint8_t b = (uint8_t)(1 + below(255));
            in[i] = zeros == 0 ? b : zeros == 1 ? (below(50) ? b : 0) : zeros == 2 ? (below(2) ? b : 0) : 0;
        }
        size_t m = mar_cobs_encode(in, n, out);
        CHECK(m <= MAR_COBS_MAX(n), "COBS of %zu bytes is %zu long", n, m);
        CHECK(memchr(out, 0, m) == NULL, "COBS output holds 0x00 (n %zu)", n);
        long k = mar_cobs_decode(out, m, back, n + 1);
        CHECK(k == (long)n && memcmp(in, back, n) == 0, "COBS round trip of %zu bytes: %ld", n, k);
        k = mar_cobs_decode(out, m, back, n ? n - 1 : 0);    /* one byte short: refused, in bounds */
        CHECK(n == 0 || k == -2, "COBS too small a buffer: %ld", k);
        k = mar_cobs_decode(out, m, out, m);                  /* in place */
        CHECK(k == (long)n && memcmp(in, out, n) == 0, "COBS in place, %zu bytes", n);
        /* corrupted encodings never read or write out of bounds */
        if (m > 0) {
            uint8_t *bad = malloc(m);
            memcpy(bad, out, m);
            mar_cobs_encode(in, n, bad);
            bad[below((uint32_t)m)] = (uint8_t)below(256);
            k = mar_cobs_decode(bad, m, back, n + 1);
            CHECK(k >= -2 && k <= (long)n + 1, "corrupt COBS gave %ld", k);
            free(bad);
        }
        free(in);
        free(out);
        free(back);
    }
    uint8_t z[2] = { 1, 0 }, d[4];
    CHECK(mar_cobs_decode(z, 2, d, 4) == -1, "0x00 inside an encoding accepted");
    uint8_t past[2] = { 5, 1 };
    CHECK(mar_cobs_decode(past, 2, d, 4) == -1, "code byte past the end accepted");
    CHECK(mar_cobs_decode(z, 0, d, 4) == -1, "empty encoding accepted");
    uint8_t run[256], data[254];
    run[0] = 0xFF;
    for (int i = 0; i < 254; i++)
        run[1 + i] = data[i] = (uint8_t)(1 + i);
    run[255] = 1;
    uint8_t back[254];
    CHECK(mar_cobs_decode(run, 256, back, 254) == 254 && memcmp(back, data, 254) == 0,
          "254-byte run with its final 01 refused");
    CHECK(mar_cobs_decode(run, 255, back, 254) == -1, "254-byte run without its final 01 accepted");
}

static size_t wire_size(const mar_msg *m)
{
    uint8_t tmp[MAR_WIRE_MAX];
    long n = mar_encode_frame(m, tmp, sizeof tmp);
    return n < 0 ? 0 : (size_t)n;
}

static void test_serial_round_trips(int cases)
{
    mar_deframer d;
    mar_deframer_init(&d);
    for (int c = 0; c < cases; c++) {
        mar_msg m, out;
        mar_fuzz_random_msg(&rng, &m, c % 3 == 0);
        size_t size = wire_size(&m);
        CHECK(size > 0 && size <= MAR_WIRE_MAX, "type %02x: %zu wire bytes", m.type, size);
        uint8_t *w = malloc(size);
        CHECK(mar_encode_frame(&m, w, size) == (long)size, "exact-size buffer refused");
        CHECK(mar_encode_frame(&m, w, size - 1) == MAR_E_SHORT, "short buffer accepted");
        CHECK(w[size - 1] == 0 && memchr(w, 0, size - 1) == NULL, "delimiter");
        memset(&out, 0xA5, sizeof out);
        CHECK(mar_decode_frame(w, size, &out) == 0 && mar_msg_equal(&m, &out),
              "round trip of type %02x", m.type);
        int got = 0;
        for (size_t i = 0; i < size; i++) {
            int r = mar_deframer_push(&d, w[i], &out);
            CHECK(r == (i + 1 == size), "deframer %d at byte %zu of %zu", r, i, size);
            got += r == 1;
        }
        CHECK(got == 1 && mar_msg_equal(&m, &out), "deframed type %02x", m.type);
        /* every truncation is refused */
        for (size_t cut = 0; cut + 1 < size; cut++) {
            uint8_t *t = malloc(cut + 1);
            memcpy(t, w, cut);
            t[cut] = 0;
            CHECK(mar_decode_frame(t, cut + 1, &out) < 0, "frame cut to %zu of %zu accepted", cut, size);
            free(t);
        }
        /* every single flipped bit of the body is caught (Hamming distance 6 > 1) */
        uint8_t body[MAR_FRAME_MAX];
        long n = mar_encode_body(&m, body, sizeof body);
        for (long bit = 0; bit < 8 * n; bit += 1 + (long)below(7)) {
            body[bit / 8] ^= (uint8_t)(1u << (bit % 8));
            CHECK(mar_decode_body(body, (size_t)n, &out) < 0, "bit %ld of %ld flipped, accepted", bit, 8 * n);
            body[bit / 8] ^= (uint8_t)(1u << (bit % 8));
        }
        free(w);
    }
    CHECK(d.frames_ok == (uint32_t)cases && d.crc_errors == 0 && d.garbage_bytes == 0,
          "deframer counters: %u ok, %u crc", (unsigned)d.frames_ok, (unsigned)d.crc_errors);
}

/* A body with a correct CRC over whatever bytes are given. */
static size_t seal(uint8_t *body, size_t payload)
{
    size_t len = MAR_HEADER_BYTES + payload + MAR_CRC_BYTES;
    uint32_t crc = mar_crc32c(body, len - 4);
    for (int i = 0; i < 4; i++)
        body[len - 4 + i] = (uint8_t)(crc >> (8 * i));
    return len;
}

static void header(uint8_t *b, uint8_t version, uint8_t type, uint8_t node, uint32_t seq)
{
    b[0] = version;
    b[1] = type;
    b[2] = node;
    for (int i = 0; i < 4; i++)
        b[3 + i] = (uint8_t)(seq >> (8 * i));
}

static void test_refusals(void)
{
    uint8_t b[MAR_FRAME_MAX + 8], *p = b + MAR_HEADER_BYTES;
    mar_msg m;
    header(b, 2, MAR_MSG_SYNC, 0xFF, 77);
    p[0] = 0xFF;
    CHECK(mar_decode_body(b, seal(b, 1), &m) == MAR_E_VERSION && m.seq == 77 && m.type == MAR_MSG_SYNC,
          "other version");
    header(b, 1, 0x42, 3, 5);
    CHECK(mar_decode_body(b, seal(b, 0), &m) == MAR_E_TYPE && m.node == 3, "unknown type");
    header(b, 1, MAR_MSG_SYNC, 0xFF, 1);
    CHECK(mar_decode_body(b, seal(b, 2), &m) == MAR_E_LENGTH, "SYNC of 2 bytes");
    header(b, 1, MAR_MSG_SYNC, 4, 1);
    CHECK(mar_decode_body(b, seal(b, 1), &m) == MAR_E_VALUE, "SYNC to one node");
    header(b, 1, MAR_MSG_STATUS, 4, 1);
    memset(p, 0, 9);
    p[1] = MAR_STATE_OPERATIONAL;
    CHECK(mar_decode_body(b, seal(b, 9), &m) == MAR_E_LENGTH, "STATUS with 3 position bytes");
    CHECK(mar_decode_body(b, seal(b, 6), &m) == 0 && m.status.n == 0, "STATUS without positions");
    p[0] = 0x20;
    CHECK(mar_decode_body(b, seal(b, 6), &m) == MAR_E_VALUE, "reserved flag accepted");
    p[0] = 0;
    p[1] = 9;
    CHECK(mar_decode_body(b, seal(b, 6), &m) == MAR_E_VALUE, "unknown state accepted");
    header(b, 1, MAR_MSG_SETPOINT, 0xFF, 1);
    p[0] = 1, p[1] = 0, p[2] = 0;
    CHECK(mar_decode_body(b, seal(b, 3), &m) == MAR_E_LENGTH, "empty group accepted");
    p[2] = 2;
    CHECK(mar_decode_body(b, seal(b, 3 + 4), &m) == MAR_E_LENGTH, "group longer than its payload");
    CHECK(mar_decode_body(b, seal(b, 3 + 8), &m) == 0 && m.setpoint.n == 2, "group of two");
    p[1] = 255;
    CHECK(mar_decode_body(b, seal(b, 3 + 8), &m) == MAR_E_VALUE, "channel past 255 accepted");
    p[0] = 0xFF, p[1] = 0;
    CHECK(mar_decode_body(b, seal(b, 3 + 8), &m) == MAR_E_VALUE, "broadcast node in a group");
    header(b, 1, MAR_MSG_SETPOINT, 0xFF, 1);
    CHECK(mar_decode_body(b, seal(b, 0), &m) == MAR_E_LENGTH, "SETPOINT without entries");
    header(b, 1, MAR_MSG_LOUDNESS, 2, 1);
    float bad[3] = { NAN, INFINITY, -1.0f };
    for (int i = 0; i < 3; i++) {
        memcpy(p, &bad[i], 4);      /* little-endian host assumed by this test */
        CHECK(mar_decode_body(b, seal(b, 4), &m) == MAR_E_VALUE, "loudness %g accepted", (double)bad[i]);
    }
    /* LOUDNESS with bands: 4 bytes of loudness, a count k, k codes; a
     * count that disagrees with the length is refused */
    memset(p, 0, 5 + MAR_BANDS_MAX + 2);
    CHECK(mar_decode_body(b, seal(b, 4), &m) == 0 && m.loudness.n_bands == 0, "one-band LOUDNESS");
    for (size_t len = 5; len <= 5 + MAR_BANDS_MAX + 1; len++)
        for (unsigned k = 0; k <= MAR_BANDS_MAX + 2; k++) {
            header(b, 1, MAR_MSG_LOUDNESS, 2, 1);
            memset(p, 0, 4);
            p[4] = (uint8_t)k;
            for (size_t i = 5; i < len; i++)
                p[i] = (uint8_t)(i * 37);
            int r = mar_decode_body(b, seal(b, len), &m);
            int want = k == 0 || len != 5 + k ? MAR_E_LENGTH : k > MAR_BANDS_MAX ? MAR_E_VALUE : 0;
            CHECK(r == want, "LOUDNESS of %zu bytes with count %u: %d, not %d", len, k, r, want);
            CHECK(r != 0 || (m.loudness.n_bands == k && m.loudness.band[k - 1] == (uint8_t)((len - 1) * 37)),
                  "LOUDNESS bands read back (count %u)", k);
        }
    header(b, 1, MAR_MSG_CONFIG, 2, 1);
    memset(p, 0, 6 + 17);
    CHECK(mar_decode_body(b, seal(b, 6 + 16), &m) == MAR_E_LENGTH, "CONFIG of 22 bytes");
    CHECK(mar_decode_body(b, seal(b, 6 + 17), &m) == 0 && m.config.n == 1, "CONFIG of one channel");
    CHECK(mar_config_reason(&m) == MAR_REASON_BAD_CONFIG, "zero speed config accepted by the node check");
    header(b, 1, MAR_MSG_ESTOP, 0xFF, 1);
    CHECK(mar_decode_body(b, seal(b, 1), &m) == MAR_E_LENGTH, "ESTOP with a payload");
    CHECK(mar_decode_body(b, 10, &m) == MAR_E_SHORT, "short body");
    CHECK(mar_decode_body(b, MAR_FRAME_MAX + 1, &m) == MAR_E_TOOLONG, "long body");

    /* the encoder refuses what the decoder would */
    uint8_t w[MAR_WIRE_MAX];
    memset(&m, 0, sizeof m);
    m.type = MAR_MSG_SETPOINT;
    m.node = 0xFF;
    CHECK(mar_encode_frame(&m, w, sizeof w) == MAR_E_VALUE, "no entries");
    m.setpoint.n = MAR_SETPOINT_MAX + 1;
    CHECK(mar_encode_frame(&m, w, sizeof w) == MAR_E_RANGE, "61 entries");
    m.setpoint.n = MAR_SETPOINT_MAX;        /* 60 entries, each its own group: too big */
    for (int i = 0; i < MAR_SETPOINT_MAX; i++)
        m.setpoint.entry[i] = (mar_setpoint_entry){ (uint8_t)i, 0, i };
    CHECK(mar_encode_frame(&m, w, sizeof w) == MAR_E_RANGE, "60 groups");
    for (int i = 0; i < MAR_SETPOINT_MAX; i++)
        m.setpoint.entry[i] = (mar_setpoint_entry){ 7, (uint8_t)i, -i };
    CHECK(mar_encode_frame(&m, w, sizeof w) > 0, "60 entries in one group");
    m.type = MAR_MSG_STATUS;
    m.node = 1;
    m.status.state = MAR_STATE_OPERATIONAL;
    m.status.flags = 0x40;
    CHECK(mar_encode_frame(&m, w, sizeof w) == MAR_E_VALUE, "reserved flag");
    m.status.flags = 0;
    m.status.n = MAR_STATUS_MAX + 1;
    CHECK(mar_encode_frame(&m, w, sizeof w) == MAR_E_RANGE, "60 positions");
    m.type = MAR_MSG_LOUDNESS;
    m.loudness.value = NAN;
    CHECK(mar_encode_frame(&m, w, sizeof w) == MAR_E_VALUE, "NaN loudness");
    m.loudness.value = 0.5f;
    m.loudness.n_bands = MAR_BANDS_MAX + 1;
    CHECK(mar_encode_frame(&m, w, sizeof w) == MAR_E_RANGE, "17 bands");
    m.loudness.n_bands = MAR_BANDS_MAX;
    CHECK(mar_encode_frame(&m, w, sizeof w) > 0, "16 bands");
    m.type = MAR_MSG_CONFIG;
    m.node = 0xFF;
    CHECK(mar_encode_frame(&m, w, sizeof w) == MAR_E_VALUE, "CONFIG to every node");
    m.type = 0x7E;
    CHECK(mar_encode_frame(&m, w, sizeof w) == MAR_E_TYPE, "unknown type");
}

static void test_deframer_resync(void)
{
    mar_deframer d;
    mar_deframer_init(&d);
    uint32_t good = 0;
    for (int round = 0; round < 2000; round++) {
        mar_msg m, out;
        uint8_t w[MAR_WIRE_MAX];
        /* garbage: random bytes, or a long run without 0x00 (overlong) */
        size_t k = below(3) ? below(600) : 300 + below(2000);
        int runaway = below(2);
        for (size_t i = 0; i < k; i++) {
            uint8_t g = (uint8_t)below(256);
            if (runaway && g == 0)
                g = 1;
            CHECK(mar_deframer_push(&d, g, &out) != 1 || k < 12, "garbage decoded");
        }
        mar_fuzz_random_msg(&rng, &m, 0);
        long n = mar_encode_frame(&m, w, sizeof w);
        /* a 0x00 ends the garbage; a sender may put one before every frame */
        mar_deframer_push(&d, 0, &out);
        int got = 0;
        for (long i = 0; i < n; i++)
            got += mar_deframer_push(&d, w[i], &out) == 1;
        CHECK(got == 1 && mar_msg_equal(&m, &out), "frame after %zu bytes of garbage lost", k);
        good += got;
    }
    CHECK(d.frames_ok >= good, "frames_ok %u", (unsigned)d.frames_ok);
    CHECK(d.too_long > 0 && d.garbage_bytes > 0 && d.crc_errors + d.cobs_errors + d.too_short > 0,
          "garbage counted: too long %u, garbage bytes %u", (unsigned)d.too_long, (unsigned)d.garbage_bytes);
    /* a run longer than the buffer is dropped at its 0x00, and counted */
    mar_deframer_init(&d);
    mar_msg out;
    for (int i = 0; i < 5000; i++)
        mar_deframer_push(&d, 0x55, &out);
    CHECK(mar_deframer_push(&d, 0, &out) == MAR_E_TOOLONG && d.too_long == 1 && d.garbage_bytes == 5000,
          "overlong run");
    CHECK(mar_deframer_push(&d, 0, &out) == 0, "empty frame not ignored");
}

static void test_setpoint_batches(void)
{
    mar_deframer d;
    mar_deframer_init(&d);
    enum { MAXN = 600 };
    static mar_setpoint_entry in[MAXN], got[MAXN];
    for (int round = 0; round < 400; round++) {
        size_t n = below(MAXN + 1);
        int sorted = below(2);
        for (size_t i = 0; i < n; i++)
            in[i] = sorted ? (mar_setpoint_entry){ (uint8_t)(i / 40), (uint8_t)(i % 40), (int32_t)below(100000) - 50000 }
                           : (mar_setpoint_entry){ (uint8_t)below(255), (uint8_t)below(256), (int32_t)mar_fuzz_next(&rng) };
        size_t cap = mar_setpoints_wire_max(n);
        uint8_t *w = malloc(cap + 1);
        uint32_t tick = (uint32_t)mar_fuzz_next(&rng);
        long len = mar_encode_setpoints(tick, in, n, w, cap);
        CHECK(len >= 0 && (size_t)len <= cap, "batch of %zu: %ld of %zu bytes", n, len, cap);
        size_t k = 0;
        mar_msg out;
        for (long i = 0; i < len; i++)
            if (mar_deframer_push(&d, w[i], &out) == 1) {
                CHECK(out.type == MAR_MSG_SETPOINT && out.seq == tick, "batch frame header");
                for (size_t j = 0; j < out.setpoint.n && k < MAXN; j++)
                    got[k++] = out.setpoint.entry[j];
            }
        int same = k == n;
        for (size_t i = 0; same && i < n; i++)
            same = got[i].node == in[i].node && got[i].channel == in[i].channel && got[i].counts == in[i].counts;
        CHECK(same, "batch of %zu entries (%s) came back as %zu", n, sorted ? "sorted" : "shuffled", k);
        if (n > 0)
            CHECK(mar_encode_setpoints(tick, in, n, w, (size_t)len - 1) == MAR_E_SHORT, "short batch buffer");
        free(w);
    }
    mar_setpoint_entry bad = { 0xFF, 0, 0 };
    uint8_t w[MAR_WIRE_MAX];
    CHECK(mar_encode_setpoints(0, &bad, 1, w, sizeof w) == MAR_E_VALUE, "broadcast node in a batch");
    CHECK(mar_encode_setpoints(0, NULL, 0, w, sizeof w) == 0, "empty batch");
}

/* What comes back over CAN: seq not carried, ticks modulo 256 from a fresh receiver. */
static void can_canonical(mar_msg *m)
{
    if (m->type == MAR_MSG_SYNC || m->type == MAR_MSG_STATUS || m->type == MAR_MSG_SETPOINT)
        m->seq &= 0xFFu;
}

static void shuffle(mar_can_frame *f, size_t n)
{
    for (size_t i = n; i > 1; i--) {
        size_t j = below((uint32_t)i);
        mar_can_frame t = f[i - 1];
        f[i - 1] = f[j];
        f[j] = t;
    }
}

static void test_can(int cases)
{
    mar_can_rx *rx = malloc(sizeof *rx);
    mar_can_frame *f = malloc(MAR_CAN_FRAMES_MAX * sizeof *f);
    for (int c = 0; c < cases; c++) {
        mar_msg m, out, sync;
        mar_fuzz_random_msg(&rng, &m, 1);
        long n = mar_can_encode(&m, f, MAR_CAN_FRAMES_MAX);
        CHECK(n > 0, "CAN encode of type %02x: %ld", m.type, n);
        if (n <= 0)
            continue;
        CHECK(mar_can_encode(&m, f, (size_t)n - 1) < 0, "CAN short buffer accepted");
        mar_can_encode(&m, f, (size_t)n);
        mar_can_rx_init(rx);
        can_canonical(&m);
        if (m.type == MAR_MSG_SETPOINT) {
            mar_can_frame s = { MAR_CAN_SYNC, 1, { (uint8_t)m.seq, 0, 0, 0, 0, 0, 0, 0 } };
            CHECK(mar_can_rx_feed(rx, &s, &sync) == 1 && sync.seq == m.seq, "SYNC");
            size_t k = 0;
            int same = 1;
            for (long i = 0; i < n; i++) {
                CHECK(f[i].dlc == 8, "PDO DLC %d", f[i].dlc);
                int r = mar_can_rx_feed(rx, &f[i], &out);
                CHECK(r == 1 && out.seq == m.seq, "setpoint PDO %ld: %d", i, r);
                for (size_t j = 0; r == 1 && j < out.setpoint.n; j++, k++)
                    same = same && k < m.setpoint.n && out.setpoint.entry[j].node == m.setpoint.entry[k].node
                        && out.setpoint.entry[j].channel == m.setpoint.entry[k].channel
                        && out.setpoint.entry[j].counts == m.setpoint.entry[k].counts;
            }
            CHECK(same && k == m.setpoint.n, "CAN setpoints round trip (%zu of %u)", k, m.setpoint.n);
            /* a PDO of another tick is stale */
            s.data[0] = (uint8_t)(m.seq + 1 + below(15));
            mar_can_rx_feed(rx, &s, &sync);
            CHECK(mar_can_rx_feed(rx, &f[0], &out) == MAR_E_STALE, "stale PDO accepted");
            continue;
        }
        if (m.type == MAR_MSG_STATUS)
            shuffle(f, (size_t)n);      /* joined in any order */
        int r = 0;
        for (long i = 0; i < n; i++) {
            r = mar_can_rx_feed(rx, &f[i], &out);
            CHECK(r == (i + 1 == n), "CAN frame %ld of %ld (type %02x): %d", i, n, m.type, r);
        }
        CHECK(r == 1 && mar_msg_equal(&m, &out), "CAN round trip of type %02x", m.type);
        if (m.type == MAR_MSG_CONFIG && m.config.n > 0) {      /* a lost parameter spoils APPLY */
            mar_can_rx_init(rx);
            size_t lost = 2 + below((uint32_t)n - 3);
            for (long i = 0; i < n; i++)
                if ((size_t)i != lost)
                    r = mar_can_rx_feed(rx, &f[i], &out);
            CHECK(r == MAR_E_INCOMPLETE, "config with frame %zu lost: %d", lost, r);
        }
    }
    /* values the mapping cannot carry */
    mar_msg m;
    memset(&m, 0, sizeof m);
    m.type = MAR_MSG_SETPOINT;
    m.node = 0xFF;
    m.setpoint.n = 1;
    m.setpoint.entry[0] = (mar_setpoint_entry){ 1, 9, 0 };
    CHECK(mar_can_encode(&m, f, MAR_CAN_FRAMES_MAX) == MAR_E_VALUE, "channel 9 on CAN");
    m.setpoint.entry[0] = (mar_setpoint_entry){ 128, 0, 0 };
    CHECK(mar_can_encode(&m, f, MAR_CAN_FRAMES_MAX) == MAR_E_VALUE, "node 128 on CAN");
    m.setpoint.entry[0] = (mar_setpoint_entry){ 0, 0, 0 };
    CHECK(mar_can_encode(&m, f, MAR_CAN_FRAMES_MAX) == MAR_E_VALUE, "node 0 on CAN");
    m.setpoint.entry[0] = (mar_setpoint_entry){ 1, 0, MAR_CAN_COUNTS_MAX + 1 };
    CHECK(mar_can_encode(&m, f, MAR_CAN_FRAMES_MAX) == MAR_E_RANGE, "int20 overflow");
    /* the tick's encoder saturates instead */
    mar_setpoint_entry e[2] = { { 1, 0, INT32_MAX }, { 1, 1, INT32_MIN } };
    mar_msg out, sync;
    CHECK(mar_can_encode_setpoints(5, e, 2, f, 2) == 1, "two channels, one PDO");
    mar_can_rx_init(rx);
    mar_can_frame s = { MAR_CAN_SYNC, 1, { 5, 0, 0, 0, 0, 0, 0, 0 } };
    mar_can_rx_feed(rx, &s, &sync);
    CHECK(mar_can_rx_feed(rx, &f[0], &out) == 1 && out.setpoint.n == 2
          && out.setpoint.entry[0].counts == MAR_CAN_COUNTS_MAX
          && out.setpoint.entry[1].counts == -MAR_CAN_COUNTS_MAX, "saturation");
    /* SYNC counter unwrapping over 256 */
    uint32_t expect = 5;
    for (int i = 0; i < 1000; i++) {
        expect += 1 + below(100);
        s.data[0] = (uint8_t)expect;
        CHECK(mar_can_rx_feed(rx, &s, &sync) == 1 && sync.seq == expect, "unwrapped tick %u", (unsigned)expect);
    }
    /* identifiers and lengths outside the mapping */
    mar_can_frame odd[] = { { 0x000, 0, { 0 } }, { 0x180, 8, { 0 } }, { 0x581, 8, { 0 } },
                            { 0x7FF, 1, { 0 } }, { 0x080, 2, { 0 } }, { 0x701, 8, { 0 } },
                            { 0x281, 9, { 0 } } };
    for (size_t i = 0; i < sizeof odd / sizeof odd[0]; i++)
        CHECK(mar_can_rx_feed(rx, &odd[i], &out) < 0, "odd frame %03x/%d accepted", odd[i].id, odd[i].dlc);
    free(rx);
    free(f);
}

static void test_band_codes(void)
{
    CHECK(mar_band_code(6.0f) == 0 && mar_band_code(40.0f) == 0, "top code");
    CHECK(mar_band_code(5.76f) == 0 && mar_band_code(5.74f) == 1, "rounding to 0.5 dB");
    CHECK(mar_band_code(-121.0f) == 254 && mar_band_code(-121.2f) == 254, "lowest code");
    CHECK(mar_band_code(-121.3f) == MAR_BAND_SILENT && mar_band_code(-INFINITY) == (int)MAR_BAND_SILENT,
          "silent code");
    CHECK(mar_band_code(NAN) == MAR_E_VALUE && mar_band_code(INFINITY) == MAR_E_VALUE, "NaN, +inf");
    CHECK(isinf(mar_band_db(MAR_BAND_SILENT)) && mar_band_db(MAR_BAND_SILENT) < 0, "silent level");
    for (int c = 0; c < 255; c++)
        CHECK(mar_band_code(mar_band_db((uint8_t)c)) == c, "code %d does not come back", c);
    for (int i = 0; i < 20000; i++) {         /* any level in range: within half a step */
        float db = MAR_BAND_TOP_DB - (float)below(1270000) / 10000.0f;
        int c = mar_band_code(db);
        CHECK(c >= 0 && c < 255 && fabsf(mar_band_db((uint8_t)c) - db) <= 0.25f + 1e-4f,
              "%g dB -> code %d (%g dB)", (double)db, c, (double)mar_band_db((uint8_t)c));
    }
}

static void test_can_bands(void)
{
    mar_can_rx rx;
    mar_msg m, out;
    mar_can_frame f[2], odd;
    memset(&m, 0, sizeof m);
    m.type = MAR_MSG_LOUDNESS;
    m.node = 9;
    m.seq = 0x12345678u;
    m.loudness.value = 0.25f;
    m.loudness.n_bands = 6;
    memcpy(m.loudness.band, (uint8_t[]){ 0, 40, 80, 120, 254, 255 }, 6);
    CHECK(mar_can_encode(&m, f, 2) == 2 && f[0].id == MAR_CAN_BANDS + 9 && f[1].id == MAR_CAN_LOUDNESS + 9
          && f[0].dlc == 8 && f[0].data[0] == 0x68 && f[0].data[7] == 0, "bands frame, then LOUDNESS");
    mar_can_rx_init(&rx);
    CHECK(mar_can_rx_feed(&rx, &f[0], &out) == 0 && mar_can_rx_feed(&rx, &f[1], &out) == 1
          && mar_msg_equal(&m, &out), "bands joined");
    /* a LOUDNESS whose bands frame was lost: the loudness alone */
    CHECK(mar_can_rx_feed(&rx, &f[1], &out) == 1 && out.loudness.n_bands == 0, "bands used twice");
    /* bands of another frame (a LOUDNESS lost in between) are dropped */
    odd = f[0];
    odd.data[0] = (uint8_t)((odd.data[0] & 0xF0u) | ((odd.data[0] + 15u) & 0xFu));
    CHECK(mar_can_rx_feed(&rx, &odd, &out) == 0 && mar_can_rx_feed(&rx, &f[1], &out) == 1
          && out.loudness.n_bands == 0, "stale bands joined");
    /* another node's bands are not this node's */
    odd = f[0];
    odd.id = MAR_CAN_BANDS + 10;
    CHECK(mar_can_rx_feed(&rx, &odd, &out) == 0 && mar_can_rx_feed(&rx, &f[1], &out) == 1
          && out.loudness.n_bands == 0, "another node's bands joined");
    /* malformed bands frames: count 0 or 8+, reserved bytes, DLC other than 8 */
    for (unsigned k = 0; k < 16; k++)
        for (int junk = 0; junk < 2; junk++) {
            odd = f[0];
            memset(odd.data + 1, 0, 7);
            memset(odd.data + 1, 7, k < 7 ? k : 7);
            odd.data[0] = (uint8_t)((k << 4) | 8u);
            if (junk)
                odd.data[7] = 7;        /* a reserved byte when k < 7 */
            int want = k >= 1 && k <= MAR_CAN_BANDS_MAX && !(junk && k < 7) ? 0 : MAR_E_VALUE;
            CHECK(mar_can_rx_feed(&rx, &odd, &out) == want, "bands count %u junk %d", k, junk);
            int r = mar_can_rx_feed(&rx, &f[1], &out);
            CHECK(r == 1 && out.loudness.n_bands == (want == 0 ? k : 0u), "after count %u: %u bands",
                  k, out.loudness.n_bands);
        }
    for (uint8_t dlc = 0; dlc < 8; dlc++) {
        odd = f[0];
        odd.dlc = dlc;
        CHECK(mar_can_rx_feed(&rx, &odd, &out) == MAR_E_LENGTH, "bands frame of DLC %u", dlc);
    }
    m.loudness.n_bands = MAR_CAN_BANDS_MAX + 1;
    CHECK(mar_can_encode(&m, f, 2) == MAR_E_RANGE, "8 bands on CAN");
    m.loudness.n_bands = 1;
    CHECK(mar_can_encode(&m, f, 1) == MAR_E_SHORT, "two frames in a buffer of one");
}

static void test_fuzz(void)
{
    mar_fuzz_report r;
    mar_fuzz_run(7, 60000, &r);
    CHECK(r.frames == 60000 && r.clean > 0 && r.clean_lost == 0, "clean frames lost: %llu",
          (unsigned long long)r.clean_lost);
    CHECK(r.low_weight > 0 && r.low_weight_accepted == 0, "low-weight errors accepted: %llu",
          (unsigned long long)r.low_weight_accepted);
    CHECK(r.accepted_corrupt == 0 && r.garbage_accepted == 0, "corrupt accepted: %llu, garbage %llu",
          (unsigned long long)r.accepted_corrupt, (unsigned long long)r.garbage_accepted);
    CHECK(r.crc_trials > 5000 && r.mutated_rejected > 10000 && r.can_frames > 0, "coverage");
    mar_fuzz_report again;
    mar_fuzz_run(7, 60000, &again);
    CHECK(memcmp(&r, &again, sizeof r) == 0, "fuzz not reproducible");
}

int main(void)
{
    test_crc();
    test_cobs();
    test_serial_round_trips(4000);
    test_refusals();
    test_deframer_resync();
    test_setpoint_batches();
    test_can(20000);
    test_band_codes();
    test_can_bands();
    test_fuzz();
    if (failures) {
        fprintf(stderr, "%d checks failed\n", failures);
        return 1;
    }
    printf("protocol tests passed\n");
    return 0;
}
