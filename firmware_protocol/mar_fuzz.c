#include "mar_fuzz.h"

#include <string.h>

#include "mar_cobs.h"
#include "mar_crc.h"
#include "mar_deframer.h"
#include "mar_proto_can.h"

uint64_t mar_fuzz_next(uint64_t *state)
{
    uint64_t x = *state;
    x ^= x >> 12;
    x ^= x << 25;
    x ^= x >> 27;
    *state = x;
    return x * UINT64_C(2685821657736338717);
}

static uint32_t below(uint64_t *s, uint32_t n)     /* uniform enough in 0 .. n-1 */
{
    return (uint32_t)((mar_fuzz_next(s) >> 32) % n);
}

static int32_t as_int32(uint32_t u)
{
    return u <= 0x7FFFFFFFu ? (int32_t)u : (int32_t)(u - 0x80000000u) - INT32_MAX - 1;
}

/* Counts with the values that matter: 0, small, extremes, zero bytes, random. */
static int32_t random_counts(uint64_t *s, int can)
{
    uint32_t r = (uint32_t)(mar_fuzz_next(s) >> 32);
    int32_t limit = can ? MAR_CAN_COUNTS_MAX : INT32_MAX;
    switch (below(s, 6)) {
    case 0:
        return 0;
    case 1:
        return (int32_t)(r % 601) - 300;
    case 2:
        return r & 1 ? limit : (can ? -limit : INT32_MIN);
    case 3:
        r &= 0xFF00FF00u;
        break;
    default:
        break;
    }
    int32_t v = as_int32(r);
    if (can)
        v = (int32_t)(r % (2u * MAR_CAN_COUNTS_MAX + 1u)) - MAR_CAN_COUNTS_MAX;
    return v;
}

static uint8_t random_state(uint64_t *s)
{
    static const uint8_t states[4] = { MAR_STATE_BOOT, MAR_STATE_STOPPED, MAR_STATE_OPERATIONAL,
                                       MAR_STATE_PRE_OPERATIONAL };
    return states[below(s, 4)];
}

/* k distinct values of 0 .. n-1 (n <= 256) in ascending order, or shuffled. */
static void distinct(uint64_t *s, uint8_t *out, size_t k, unsigned n, int ascending)
{
    uint8_t pool[256];
    for (unsigned i = 0; i < n; i++)
        pool[i] = (uint8_t)i;
    for (size_t i = 0; i < k; i++) {             /* partial Fisher-Yates */
        size_t j = i + below(s, (uint32_t)(n - i));
        uint8_t t = pool[i];
        pool[i] = pool[j];
        pool[j] = t;
    }
    memcpy(out, pool, k);
    if (ascending)
        for (size_t i = 1; i < k; i++)
            for (size_t j = i; j > 0 && out[j - 1] > out[j]; j--) {
                uint8_t t = out[j];
                out[j] = out[j - 1];
                out[j - 1] = t;
            }
}

static void random_setpoints(uint64_t *s, mar_msg *m, int can)
{
    size_t n = 0;
    if (can) {          /* a few nodes, ascending, each with some of its channels 0..8 */
        uint8_t nodes[4], channels[MAR_CAN_CHANNELS];
        size_t k = 1 + below(s, 4);
        distinct(s, nodes, k, 127, 1);
        for (size_t i = 0; i < k; i++) {
            size_t c = 1 + below(s, MAR_CAN_CHANNELS);
            distinct(s, channels, c, MAR_CAN_CHANNELS, 1);
            for (size_t j = 0; j < c; j++, n++)
                m->setpoint.entry[n] = (mar_setpoint_entry){ (uint8_t)(nodes[i] + 1), channels[j],
                                                             random_counts(s, 1) };
        }
    } else {            /* runs of consecutive channels, as long as the payload has room */
        size_t want = 1 + below(s, MAR_SETPOINT_MAX), room = MAR_PAYLOAD_MAX;
        while (n < want && room >= 7) {
            size_t k = 1 + below(s, (uint32_t)(want - n));
            if (3 + 4 * k > room)
                k = (room - 3) / 4;
            uint8_t node = (uint8_t)below(s, 255), first = (uint8_t)below(s, (uint32_t)(257 - k));
            for (size_t j = 0; j < k; j++, n++)
                m->setpoint.entry[n] = (mar_setpoint_entry){ node, (uint8_t)(first + j),
                                                             random_counts(s, 0) };
            room -= 3 + 4 * k;
        }
    }
    m->setpoint.n = (uint16_t)n;
}

void mar_fuzz_random_msg(uint64_t *s, mar_msg *m, int can)
{
    static const uint8_t types[9] = { MAR_MSG_SYNC, MAR_MSG_SETPOINT, MAR_MSG_ESTOP,
                                      MAR_MSG_ESTOP_RELEASE, MAR_MSG_CONFIG, MAR_MSG_STATUS,
                                      MAR_MSG_HEARTBEAT, MAR_MSG_LOUDNESS, MAR_MSG_NACK };
    memset(m, 0, sizeof *m);
    m->type = types[below(s, 9)];
    m->seq = (uint32_t)mar_fuzz_next(s);
    m->node = can ? (uint8_t)(1 + below(s, MAR_CAN_NODE_MAX)) : (uint8_t)below(s, 255);
    int carried = 1;            /* does CAN carry the seq of this type */
    switch (m->type) {
    case MAR_MSG_SYNC:
        m->node = MAR_BROADCAST;
        m->sync.poll = can || below(s, 3) == 0 ? MAR_BROADCAST : (uint8_t)below(s, 256);
        break;
    case MAR_MSG_SETPOINT:
        m->node = MAR_BROADCAST;
        random_setpoints(s, m, can);
        break;
    case MAR_MSG_ESTOP:
    case MAR_MSG_ESTOP_RELEASE:
        if (below(s, 4) == 0)
            m->node = MAR_BROADCAST;
        carried = 0;
        break;
    case MAR_MSG_CONFIG: {
        uint8_t channels[MAR_CONFIG_MAX];
        size_t n = below(s, can ? MAR_CAN_CHANNELS + 1 : MAR_CONFIG_MAX + 1);
        distinct(s, channels, n, can ? MAR_CAN_CHANNELS : 256, 0);
        m->config.tick_period_us = below(s, 3) ? 20000u : (uint32_t)mar_fuzz_next(s);
        m->config.watchdog_ticks = (uint16_t)mar_fuzz_next(s);
        m->config.n = (uint8_t)n;
        for (size_t i = 0; i < n; i++) {
            mar_channel_config *c = &m->config.channel[i];
            c->channel = channels[i];
            c->min_counts = random_counts(s, 0);
            c->max_counts = random_counts(s, 0);
            c->max_speed = (uint32_t)mar_fuzz_next(s);
            c->max_accel = (uint32_t)mar_fuzz_next(s);
        }
        break;
    }
    case MAR_MSG_STATUS: {
        size_t n = below(s, can ? MAR_CAN_CHANNELS + 1 : MAR_STATUS_MAX + 1);
        m->status.flags = (uint8_t)below(s, MAR_FLAGS_DEFINED + 1);
        m->status.state = random_state(s);
        m->status.rejected = (uint16_t)mar_fuzz_next(s);
        m->status.seq_gaps = (uint16_t)mar_fuzz_next(s);
        m->status.n = (uint8_t)n;
        for (size_t i = 0; i < n; i++)
            m->status.position[i] = random_counts(s, can);
        break;
    }
    case MAR_MSG_HEARTBEAT:
        m->heartbeat.state = random_state(s);
        carried = 0;
        break;
    case MAR_MSG_LOUDNESS: {
        uint32_t bits = (uint32_t)mar_fuzz_next(s) & 0x7FFFFFFFu;   /* not negative */
        if ((bits >> 23) == 0xFF)
            bits &= ~(1u << 30);                                     /* finite */
        if (below(s, 2))
            bits = 0x3F000000u + (bits & 0x7FFFFFu);                 /* 0.5 .. 1: typical */
        memcpy(&m->loudness.value, &bits, 4);
        if (below(s, 2)) {                                           /* a band node */
            m->loudness.n_bands = (uint8_t)(1 + below(s, can ? MAR_CAN_BANDS_MAX : MAR_BANDS_MAX));
            for (size_t i = 0; i < m->loudness.n_bands; i++)
                m->loudness.band[i] = (uint8_t)below(s, 256);
        }
        break;
    }
    default:    /* NACK */
        m->nack.reason = below(s, 2) ? (uint16_t)below(s, 10) : (uint16_t)mar_fuzz_next(s);
        m->nack.flags = (uint8_t)below(s, MAR_FLAGS_DEFINED + 1);
        m->nack.ref_type = (uint8_t)mar_fuzz_next(s);
        m->nack.ref_seq = (uint32_t)mar_fuzz_next(s);
        carried = 0;
        break;
    }
    if (can && !carried)
        m->seq = 0;
}

enum { BUF = 2048 };

/* Wire bytes changed in one of nine ways; returns the new length. */
static size_t mutate(uint64_t *s, uint8_t *w, size_t len)
{
    size_t at = below(s, (uint32_t)len);
    switch (below(s, 9)) {
    case 0:
        w[at] ^= (uint8_t)(1u << below(s, 8));
        break;
    case 1:
        for (uint32_t k = 2 + below(s, 7); k > 0; k--)
            w[below(s, (uint32_t)len)] ^= (uint8_t)(1u << below(s, 8));
        break;
    case 2:
        w[at] = (uint8_t)(w[at] + 1 + below(s, 255));
        break;
    case 3:
        memmove(w + at + 1, w + at, len - at);
        w[at] = (uint8_t)below(s, 256);
        return len + 1;
    case 4:
        memmove(w + at, w + at + 1, len - at - 1);
        return len - 1;
    case 5:
        return at;
    case 6: {
        size_t k = 2 + below(s, 15);
        for (size_t i = at; i < at + k && i < len; i++)
            w[i] = (uint8_t)below(s, 256);
        break;
    }
    case 7: {
        size_t b = below(s, (uint32_t)len);
        uint8_t t = w[at];
        w[at] = w[b];
        w[b] = t;
        break;
    }
    default: {  /* grown past the largest frame, or just longer */
        size_t k = 1 + below(s, 400);
        if (len == 0)
            return 0;
        for (size_t i = 0; i < k; i++)
            w[len - 1 + i] = (uint8_t)(1 + below(s, 255));
        w[len - 1 + k] = 0;
        return len + k;
    }
    }
    return len;
}

typedef struct {
    int messages, same;
} fed;

/* Feeds bytes then a 0x00 (so every piece ends); compares what comes out with orig. */
static fed feed(mar_deframer *d, const uint8_t *w, size_t len, const mar_msg *orig, mar_msg *out,
                mar_fuzz_report *r)
{
    fed f = { 0, 0 };
    r->wire_bytes += len + 1;
    for (size_t i = 0; i <= len; i++) {
        int k = mar_deframer_push(d, i < len ? w[i] : 0, out);
        if (k == 1) {
            f.messages++;
            f.same += orig && mar_msg_equal(out, orig);
        }
    }
    return f;
}

/* The CRC's trials in w: pieces that decode, once their CRC is made right,
 * to a message other than orig (only the CRC stands in their way). Adds
 * them to *trials, and to *pass16 those a check of the low 16 CRC bits
 * alone would have let through. */
static void judge_crc(const uint8_t *w, size_t len, const mar_msg *orig, mar_msg *out,
                      uint64_t *trials, uint64_t *pass16)
{
    uint8_t body[MAR_WIRE_MAX];
    size_t start = 0;
    for (size_t i = 0; i <= len; i++) {
        if (i < len && w[i] != 0)
            continue;
        size_t piece = i - start;
        long n = piece && piece < MAR_WIRE_MAX ? mar_cobs_decode(w + start, piece, body, sizeof body) : -1;
        start = i + 1;
        if (n < MAR_HEADER_BYTES + MAR_CRC_BYTES || n > MAR_FRAME_MAX)
            continue;
        size_t c = (size_t)n - MAR_CRC_BYTES;
        uint32_t crc = mar_crc32c(body, c);
        int low16 = (body[c] | body[c + 1] << 8) == (int)(crc & 0xFFFFu);
        for (int k = 0; k < 4; k++)
            body[c + k] = (uint8_t)(crc >> (8 * k));
        if (mar_decode_body(body, (size_t)n, out) == 0 && !mar_msg_equal(out, orig)) {
            (*trials)++;
            *pass16 += (uint64_t)low16;
        }
    }
}

static void fuzz_can(uint64_t *s, mar_fuzz_report *r)
{
    mar_can_rx rx;
    mar_can_frame frames[MAR_CAN_FRAMES_MAX + 1];
    mar_msg m, out;
    mar_can_rx_init(&rx);
    mar_fuzz_random_msg(s, &m, 1);
    long n = mar_can_encode(&m, frames + 1, MAR_CAN_FRAMES_MAX);
    if (n < 0)
        n = 0;
    /* a SYNC first, so setpoint PDOs are not all stale */
    frames[0] = (mar_can_frame){ MAR_CAN_SYNC, 1, { (uint8_t)m.seq, 0, 0, 0, 0, 0, 0, 0 } };
    n++;
    switch (below(s, 4)) {
    case 0: {   /* one bit of one frame */
        mar_can_frame *f = &frames[below(s, (uint32_t)n)];
        f->data[below(s, 8)] ^= (uint8_t)(1u << below(s, 8));
        break;
    }
    case 1:     /* another identifier or length */
        if (below(s, 2))
            frames[below(s, (uint32_t)n)].id = (uint16_t)below(s, 0x800);
        else
            frames[below(s, (uint32_t)n)].dlc = (uint8_t)below(s, 16);
        break;
    case 2:     /* a frame lost */
        if (n > 1) {
            size_t k = below(s, (uint32_t)n);
            memmove(frames + k, frames + k + 1, (size_t)(n - 1 - (long)k) * sizeof frames[0]);
            n--;
        }
        break;
    default:    /* random frames */
        for (long i = 0; i < n; i++) {
            frames[i].id = (uint16_t)below(s, 0x800);
            frames[i].dlc = (uint8_t)below(s, 9);
            for (int b = 0; b < 8; b++)
                frames[i].data[b] = (uint8_t)below(s, 256);
        }
    }
    for (long i = 0; i < n; i++) {
        r->can_frames++;
        r->can_messages += mar_can_rx_feed(&rx, &frames[i], &out) == 1;
    }
}

void mar_fuzz_run(uint64_t seed, uint64_t n_frames, mar_fuzz_report *r)
{
    uint64_t s = seed * UINT64_C(0x9E3779B97F4A7C15) + UINT64_C(0x2545F4914F6CDD1D);
    uint8_t w[BUF], body[MAR_FRAME_MAX];
    mar_deframer d;
    mar_msg orig, out;
    memset(r, 0, sizeof *r);
    if (s == 0)
        s = 1;
    mar_deframer_init(&d);
    for (uint64_t i = 0; i < n_frames; i++) {
        mar_fuzz_random_msg(&s, &orig, 0);
        long len = mar_encode_frame(&orig, w, sizeof w);
        if (len < 0) {          /* the generator makes only valid messages */
            r->clean_lost++;
            continue;
        }
        r->frames++;
        uint32_t kind = below(&s, 100);
        if (kind < 10) {
            fed f = feed(&d, w, (size_t)len, &orig, &out, r);
            r->clean++;
            r->clean_lost += !(f.messages == 1 && f.same == 1);
        } else if (kind < 20) {
            /* garbage, then the frame twice: the first copy may be lost to
             * the garbage, the second must come through */
            uint8_t g[400];
            size_t k = 1 + below(&s, sizeof g);
            for (size_t j = 0; j < k; j++)
                g[j] = (uint8_t)below(&s, 256);
            r->garbage_runs++;
            r->garbage_bytes += k;
            r->wire_bytes += k;
            for (size_t j = 0; j < k; j++)
                r->garbage_accepted += mar_deframer_push(&d, g[j], &out) == 1;
            for (size_t j = 0; j < (size_t)len; j++)       /* first copy, no extra 0x00 */
                if (mar_deframer_push(&d, w[j], &out) == 1 && !mar_msg_equal(&out, &orig))
                    r->garbage_accepted++;
            r->wire_bytes += (size_t)len;
            fed f = feed(&d, w, (size_t)len - 1, &orig, &out, r);
            r->clean++;
            r->clean_lost += !(f.messages == 1 && f.same == 1);
        } else if (kind < 35) {
            long n = mar_encode_body(&orig, body, sizeof body);
            uint32_t bits[5];
            size_t k = 1 + below(&s, 5);
            for (size_t j = 0; j < k; j++) {        /* k distinct bit positions */
                int again;
                do {
                    bits[j] = below(&s, (uint32_t)(8 * n));
                    again = 0;
                    for (size_t q = 0; q < j; q++)
                        again |= bits[q] == bits[j];
                } while (again);
                body[bits[j] / 8] ^= (uint8_t)(1u << (bits[j] % 8));
            }
            size_t m = mar_cobs_encode(body, (size_t)n, w);
            fed f = feed(&d, w, m, &orig, &out, r);
            r->low_weight++;
            r->low_weight_accepted += (uint64_t)f.messages;
        } else {
            size_t m = mutate(&s, w, (size_t)len);
            fed f = feed(&d, w, m, &orig, &out, r);
            r->mutated++;
            r->mutated_same += (uint64_t)f.same;
            r->accepted_corrupt += (uint64_t)(f.messages - f.same);
            r->mutated_rejected += f.messages == 0;
            judge_crc(w, m, &orig, &out, &r->crc_trials, &r->crc16_accepted);
        }
    }
    for (uint64_t i = 0; i < n_frames / 4; i++)
        fuzz_can(&s, r);
}
