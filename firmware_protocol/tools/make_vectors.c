/* Writes the golden vectors of protocol version 1: every message type, as
 * serial frames (vectors/serial.json) and as CAN frames (vectors/can.json).
 *
 *   gcc -std=c11 -I firmware_protocol firmware_protocol/mar_*.c \
 *       firmware_protocol/tools/make_vectors.c -o make_vectors
 *   ./make_vectors firmware_protocol/vectors
 *
 * Messages are written with the wire's field names (seq, not tick); CAN
 * vectors list the frames of the message ("frames", after the "prefix"
 * frames a receiver must have seen, e.g. the SYNC before setpoint PDOs) and
 * what a fresh receiver decodes from prefix + frames ("decoded").
 * vectors/refused.json holds frames a receiver must refuse, with the
 * codec's status ("error") and the NACK reason a node answers with.
 * tests/test_protocol.py checks the Python API against these files, and
 * that they equal what this program writes now. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "mar_cobs.h"
#include "mar_crc.h"
#include "mar_proto.h"
#include "mar_proto_can.h"

static const char *type_name(uint8_t t)
{
    switch (t) {
    case MAR_MSG_SYNC: return "SYNC";
    case MAR_MSG_SETPOINT: return "SETPOINT";
    case MAR_MSG_ESTOP: return "ESTOP";
    case MAR_MSG_ESTOP_RELEASE: return "ESTOP_RELEASE";
    case MAR_MSG_CONFIG: return "CONFIG";
    case MAR_MSG_STATUS: return "STATUS";
    case MAR_MSG_HEARTBEAT: return "HEARTBEAT";
    case MAR_MSG_LOUDNESS: return "LOUDNESS";
    case MAR_MSG_NACK: return "NACK";
    default: return "?";
    }
}

static void hex(FILE *f, const uint8_t *p, size_t n)
{
    fputc('"', f);
    for (size_t i = 0; i < n; i++)
        fprintf(f, "%02x", p[i]);
    fputc('"', f);
}

static void message(FILE *f, const mar_msg *m)
{
    fprintf(f, "{\"type\": \"%s\", \"node\": %u, \"seq\": %lu", type_name(m->type), m->node,
            (unsigned long)m->seq);
    switch (m->type) {
    case MAR_MSG_SYNC:
        fprintf(f, ", \"poll\": %u", m->sync.poll);
        break;
    case MAR_MSG_SETPOINT:
        fprintf(f, ", \"entries\": [");
        for (size_t i = 0; i < m->setpoint.n; i++)
            fprintf(f, "%s[%u, %u, %ld]", i ? ", " : "", m->setpoint.entry[i].node,
                    m->setpoint.entry[i].channel, (long)m->setpoint.entry[i].counts);
        fputc(']', f);
        break;
    case MAR_MSG_CONFIG:
        fprintf(f, ", \"tick_period_us\": %lu, \"watchdog_ticks\": %u, \"channels\": [",
                (unsigned long)m->config.tick_period_us, m->config.watchdog_ticks);
        for (size_t i = 0; i < m->config.n; i++) {
            const mar_channel_config *c = &m->config.channel[i];
            fprintf(f, "%s[%u, %ld, %ld, %lu, %lu]", i ? ", " : "", c->channel, (long)c->min_counts,
                    (long)c->max_counts, (unsigned long)c->max_speed, (unsigned long)c->max_accel);
        }
        fputc(']', f);
        break;
    case MAR_MSG_STATUS:
        fprintf(f, ", \"flags\": %u, \"state\": %u, \"rejected\": %u, \"seq_gaps\": %u, \"positions\": [",
                m->status.flags, m->status.state, m->status.rejected, m->status.seq_gaps);
        for (size_t i = 0; i < m->status.n; i++)
            fprintf(f, "%s%ld", i ? ", " : "", (long)m->status.position[i]);
        fputc(']', f);
        break;
    case MAR_MSG_HEARTBEAT:
        fprintf(f, ", \"state\": %u", m->heartbeat.state);
        break;
    case MAR_MSG_LOUDNESS:
        if (m->loudness.value == 0.0f && signbit(m->loudness.value))
            fprintf(f, ", \"value\": -0.0");      /* JSON's -0 would read back as 0 */
        else
            fprintf(f, ", \"value\": %.9g", (double)m->loudness.value);
        if (m->loudness.n_bands > 0) {          /* band codes, as on the wire */
            fprintf(f, ", \"bands\": [");
            for (size_t i = 0; i < m->loudness.n_bands; i++)
                fprintf(f, "%s%u", i ? ", " : "", m->loudness.band[i]);
            fputc(']', f);
        }
        break;
    case MAR_MSG_NACK:
        fprintf(f, ", \"reason\": %u, \"flags\": %u, \"ref_type\": %u, \"ref_seq\": %lu", m->nack.reason,
                m->nack.flags, m->nack.ref_type, (unsigned long)m->nack.ref_seq);
        break;
    default:
        break;
    }
    fputc('}', f);
}

static mar_msg msg(uint8_t type, uint8_t node, uint32_t seq)
{
    mar_msg m;
    memset(&m, 0, sizeof m);
    m.type = type;
    m.node = node;
    m.seq = seq;
    return m;
}

/* The vectors' messages; returns how many (at most cap). */
static size_t messages(mar_msg *out, const char **names)
{
    size_t n = 0;
    mar_msg m;

    m = msg(MAR_MSG_SYNC, MAR_BROADCAST, 0x01020304u);
    m.sync.poll = MAR_BROADCAST;
    names[n] = "sync_every_node", out[n++] = m;
    m = msg(MAR_MSG_SYNC, MAR_BROADCAST, 0);
    m.sync.poll = 3;
    names[n] = "sync_poll_node_3", out[n++] = m;

    /* the bundled figure (marionette/data/hoffmann1996.toml) at its home pose */
    static const struct { uint8_t node, channel; int32_t counts; } home[16] = {
        { 1, 0, 12000 }, { 1, 1, 12000 }, { 1, 2, 12000 }, { 1, 3, 12000 }, { 1, 4, 12000 },
        { 1, 5, 12000 }, { 1, 6, 12000 }, { 1, 7, 12000 }, { 1, 8, 12000 }, { 2, 0, 0 },
        { 3, 0, 0 }, { 4, 0, 0 }, { 5, 0, 2048 }, { 5, 1, 2048 }, { 5, 2, 2048 }, { 5, 3, 2048 } };
    m = msg(MAR_MSG_SETPOINT, MAR_BROADCAST, 1234);
    for (size_t i = 0; i < 16; i++)
        m.setpoint.entry[i] = (mar_setpoint_entry){ home[i].node, home[i].channel, home[i].counts };
    m.setpoint.n = 16;
    names[n] = "setpoints_hoffmann_home", out[n++] = m;

    m = msg(MAR_MSG_SETPOINT, MAR_BROADCAST, 0xFFFFFFFFu);
    m.setpoint.entry[0] = (mar_setpoint_entry){ 0, 0, INT32_MIN };
    m.setpoint.entry[1] = (mar_setpoint_entry){ 0, 1, INT32_MAX };
    m.setpoint.entry[2] = (mar_setpoint_entry){ 254, 255, -1 };
    m.setpoint.entry[3] = (mar_setpoint_entry){ 7, 3, 0 };
    m.setpoint.n = 4;
    names[n] = "setpoints_extremes", out[n++] = m;

    /* 60 channels of one node, no zero byte: a body of 254 bytes whose
     * COBS encoding needs a full 0xFF block */
    m = msg(MAR_MSG_SETPOINT, MAR_BROADCAST, 0x11111111u);
    for (int i = 0; i < MAR_SETPOINT_MAX; i++)
        m.setpoint.entry[i] = (mar_setpoint_entry){ 9, (uint8_t)(1 + i), 0x01010101 * (1 + i % 100) };
    m.setpoint.n = MAR_SETPOINT_MAX;
    names[n] = "setpoints_60_channels", out[n++] = m;

    /* node 2's channels 0, 1, 3: the gap starts a second group of node 2 */
    m = msg(MAR_MSG_SETPOINT, MAR_BROADCAST, 77);
    m.setpoint.entry[0] = (mar_setpoint_entry){ 2, 0, 100 };
    m.setpoint.entry[1] = (mar_setpoint_entry){ 2, 1, -100 };
    m.setpoint.entry[2] = (mar_setpoint_entry){ 2, 3, 7 };
    m.setpoint.entry[3] = (mar_setpoint_entry){ 3, 0, 0 };
    m.setpoint.n = 4;
    names[n] = "setpoints_channel_gap", out[n++] = m;

    names[n] = "estop_every_node", out[n++] = msg(MAR_MSG_ESTOP, MAR_BROADCAST, 1);
    names[n] = "estop_node_3", out[n++] = msg(MAR_MSG_ESTOP, 3, 2);
    names[n] = "estop_release_every_node", out[n++] = msg(MAR_MSG_ESTOP_RELEASE, MAR_BROADCAST, 3);

    m = msg(MAR_MSG_CONFIG, 5, 42);
    m.config.tick_period_us = 20000;
    m.config.watchdog_ticks = 5;
    m.config.channel[0] = (mar_channel_config){ 0, -3952, 8048, 8000, 40000 };
    m.config.channel[1] = (mar_channel_config){ 1, -1952, 3248, 8000, 40000 };
    m.config.n = 2;
    names[n] = "config_node_5", out[n++] = m;

    m = msg(MAR_MSG_STATUS, 1, 1234);
    m.status.flags = MAR_FLAG_LIMIT | MAR_FLAG_WATCHDOG;
    m.status.state = MAR_STATE_OPERATIONAL;
    m.status.rejected = 3;
    m.status.seq_gaps = 65535;
    for (int i = 0; i < 9; i++)
        m.status.position[i] = 12000 - 1000 * i;
    m.status.n = 9;
    names[n] = "status_node_1", out[n++] = m;

    m = msg(MAR_MSG_STATUS, 4, 7);
    m.status.state = MAR_STATE_STOPPED;
    m.status.flags = MAR_FLAG_ESTOP | MAR_FLAG_FAULT | MAR_FLAG_FOLLOWING;
    m.status.position[0] = -37500;
    m.status.n = 1;
    names[n] = "status_estop", out[n++] = m;

    m = msg(MAR_MSG_HEARTBEAT, 2, 0);
    m.heartbeat.state = MAR_STATE_BOOT;
    names[n] = "heartbeat_boot", out[n++] = m;
    m = msg(MAR_MSG_HEARTBEAT, 1, 0);
    m.heartbeat.state = MAR_STATE_PRE_OPERATIONAL;
    names[n] = "heartbeat_pre_operational", out[n++] = m;

    m = msg(MAR_MSG_LOUDNESS, 6, 1000);
    m.loudness.value = 0.5f;
    names[n] = "loudness", out[n++] = m;
    m = msg(MAR_MSG_LOUDNESS, 6, 1001);
    m.loudness.value = 0.0f;
    names[n] = "loudness_silence", out[n++] = m;
    m = msg(MAR_MSG_LOUDNESS, 6, 1002);
    m.loudness.value = -0.0f;
    names[n] = "loudness_minus_zero", out[n++] = m;
    /* six bands (the simulator's): -0 dB .. -121 dB and a silent band */
    static const uint8_t six[6] = { 12, 20, 35, 60, 254, MAR_BAND_SILENT };
    m = msg(MAR_MSG_LOUDNESS, 6, 1003);
    m.loudness.value = 0.125f;
    m.loudness.n_bands = 6;
    memcpy(m.loudness.band, six, 6);
    names[n] = "loudness_6_bands", out[n++] = m;
    m = msg(MAR_MSG_LOUDNESS, 6, 1004);     /* the most a serial LOUDNESS holds; not on CAN */
    m.loudness.value = 0.25f;
    m.loudness.n_bands = MAR_BANDS_MAX;
    for (size_t i = 0; i < MAR_BANDS_MAX; i++)
        m.loudness.band[i] = (uint8_t)(17 * i);
    names[n] = "loudness_16_bands", out[n++] = m;

    m = msg(MAR_MSG_NACK, 5, 0);
    m.nack.reason = MAR_REASON_BAD_CONFIG;
    m.nack.flags = 0;
    m.nack.ref_type = MAR_MSG_CONFIG;
    m.nack.ref_seq = 42;
    names[n] = "nack_bad_config", out[n++] = m;
    m = msg(MAR_MSG_NACK, 5, 0);
    m.nack.reason = MAR_REASON_ACCEPTED;
    m.nack.ref_type = MAR_MSG_CONFIG;
    m.nack.ref_seq = 43;
    names[n] = "nack_accepted", out[n++] = m;
    return n;
}

static int write_serial(FILE *f, const mar_msg *ms, const char **names, size_t n)
{
    fprintf(f, "[\n");
    for (size_t i = 0; i < n; i++) {
        uint8_t body[MAR_FRAME_MAX], wire[MAR_WIRE_MAX];
        long b = mar_encode_body(&ms[i], body, sizeof body);
        long w = mar_encode_frame(&ms[i], wire, sizeof wire);
        if (b < 0 || w < 0) {
            fprintf(stderr, "%s: encoding failed (%ld, %ld)\n", names[i], b, w);
            return 1;
        }
        fprintf(f, "  {\"name\": \"%s\",\n   \"message\": ", names[i]);
        message(f, &ms[i]);
        fprintf(f, ",\n   \"body\": ");
        hex(f, body, (size_t)b);
        fprintf(f, ",\n   \"wire\": ");
        hex(f, wire, (size_t)w);
        fprintf(f, "}%s\n", i + 1 < n ? "," : "");
    }
    fprintf(f, "]\n");
    return 0;
}

static void frames(FILE *f, const mar_can_frame *fr, size_t n)
{
    fputc('[', f);
    for (size_t i = 0; i < n; i++) {
        fprintf(f, "%s[%u, ", i ? ", " : "", fr[i].id);
        hex(f, fr[i].data, fr[i].dlc);
        fputc(']', f);
    }
    fputc(']', f);
}

static int write_can(FILE *f, const mar_msg *ms, const char **names, size_t n)
{
    static mar_can_rx rx;
    fprintf(f, "[\n");
    int first = 1;
    for (size_t i = 0; i < n; i++) {
        mar_can_frame fr[MAR_CAN_FRAMES_MAX], prefix[1];
        size_t np = 0;
        long k = mar_can_encode(&ms[i], fr, MAR_CAN_FRAMES_MAX);
        if (k == MAR_E_VALUE || k == MAR_E_RANGE)
            continue;           /* not carried on CAN (poll, node 0 or 254, channel 255, int32 extremes) */
        if (k < 0) {
            fprintf(stderr, "%s: CAN encoding failed (%ld)\n", names[i], k);
            return 1;
        }
        if (ms[i].type == MAR_MSG_SETPOINT)
            prefix[np++] = (mar_can_frame){ MAR_CAN_SYNC, 1, { (uint8_t)ms[i].seq, 0, 0, 0, 0, 0, 0, 0 } };
        fprintf(f, "%s  {\"name\": \"%s\",\n   \"message\": ", first ? "" : ",\n", names[i]);
        first = 0;
        message(f, &ms[i]);
        fprintf(f, ",\n   \"prefix\": ");
        frames(f, prefix, np);
        fprintf(f, ",\n   \"frames\": ");
        frames(f, fr, (size_t)k);
        fprintf(f, ",\n   \"decoded\": [");
        mar_can_rx_init(&rx);
        int count = 0;
        for (size_t j = 0; j < np + (size_t)k; j++) {
            mar_msg out;
            if (mar_can_rx_feed(&rx, j < np ? &prefix[j] : &fr[j - np], &out) == 1 && j >= np) {
                fprintf(f, "%s", count++ ? ",\n               " : "");
                message(f, &out);
            }
        }
        fprintf(f, "]}");
    }
    fprintf(f, "\n]\n");
    return 0;
}

static const char *error_name(int status)
{
    switch (status) {
    case MAR_E_COBS: return "E_COBS";
    case MAR_E_VALUE: return "E_VALUE";
    case MAR_E_LENGTH: return "E_LENGTH";
    case MAR_E_INCOMPLETE: return "E_INCOMPLETE";
    case MAR_E_STALE: return "E_STALE";
    default: return "?";
    }
}

static mar_can_frame can_frame(uint16_t id, uint8_t b0, uint8_t b1, uint8_t b2, uint32_t value)
{
    mar_can_frame f = { id, 8, { b0, b1, b2, 0, (uint8_t)value, (uint8_t)(value >> 8),
                                 (uint8_t)(value >> 16), (uint8_t)(value >> 24) } };
    return f;
}

/* Frames the decoders refuse although a careless encoder might send them. */
static int write_refused(FILE *f, const mar_msg *sixty)
{
    uint8_t wire[MAR_WIRE_MAX];
    mar_msg m;
    fprintf(f, "[\n");
    /* the optimised COBS: ff <254 bytes> 00, without the final 01 block */
    long w = mar_encode_frame(sixty, wire, sizeof wire);
    if (w < 3 || wire[w - 2] != 1)
        return 1;
    wire[w - 2] = 0;
    int r = mar_decode_frame(wire, (size_t)w - 1, &m);
    fprintf(f, "  {\"name\": \"cobs_optimised_ending\", \"link\": \"serial\", \"wire\": ");
    hex(f, wire, (size_t)w - 1);
    /* not answered: a node cannot trust the header of a frame it could not decode */
    fprintf(f, ", \"error\": \"%s\", \"reason\": null}", error_name(r));

    /* LOUDNESS whose band count disagrees with its length, or is too many;
     * sent by a node, so nobody answers it */
    static const struct { const char *name; uint8_t count, codes; } loud[] = {
        { "loudness_count_0", 0, 0 }, { "loudness_count_6_with_5_codes", 6, 5 },
        { "loudness_count_4_with_5_codes", 4, 5 }, { "loudness_17_bands", 17, 17 } };
    for (size_t i = 0; i < sizeof loud / sizeof loud[0]; i++) {
        uint8_t body[MAR_FRAME_MAX] = { MAR_PROTO_VERSION, MAR_MSG_LOUDNESS, 6, 0xEC, 0x03, 0, 0,
                                        0, 0, 0, 0x3F };     /* frame 1004, loudness 0.5 */
        size_t len = 11;
        body[len++] = loud[i].count;
        for (size_t k = 0; k < loud[i].codes; k++)
            body[len++] = (uint8_t)(40 + k);
        uint32_t crc = mar_crc32c(body, len);
        for (int k = 0; k < 4; k++)
            body[len++] = (uint8_t)(crc >> (8 * k));
        size_t e = mar_cobs_encode(body, len, wire);
        wire[e++] = 0;
        r = mar_decode_frame(wire, e, &m);
        fprintf(f, ",\n  {\"name\": \"%s\", \"link\": \"serial\", \"wire\": ", loud[i].name);
        hex(f, wire, e);
        fprintf(f, ", \"error\": \"%s\", \"reason\": null}", error_name(r));
    }

    static const mar_can_frame sync = { MAR_CAN_SYNC, 1, { 5, 0, 0, 0, 0, 0, 0, 0 } };
    mar_can_frame begin = can_frame(MAR_CAN_CONFIG + 5, MAR_CAN_PARAM_BEGIN, 0xFF, 0, 20000);
    mar_can_frame none;
    int32_t v[3] = { MAR_CAN_COUNTS_NONE, MAR_CAN_COUNTS_NONE, MAR_CAN_COUNTS_NONE };
    uint64_t bits = 5;
    for (int k = 0; k < 3; k++)
        bits |= (uint64_t)((uint32_t)v[k] & 0xFFFFFu) << (4 + 20 * k);
    none.id = MAR_CAN_SETPOINT + 5;
    none.dlc = 8;
    for (int i = 0; i < 8; i++)
        none.data[i] = (uint8_t)(bits >> (8 * i));
    const struct { const char *name; mar_can_frame prefix, frame; } can[] = {
        { "setpoint_pdo_without_channel", sync, none },
        { "config_watchdog_65536", begin, can_frame(MAR_CAN_CONFIG + 5, MAR_CAN_PARAM_WATCHDOG, 0xFF, 0, 65536) },
        { "config_begin_channel_0", sync, can_frame(MAR_CAN_CONFIG + 5, MAR_CAN_PARAM_BEGIN, 0, 0, 20000) },
        { "config_reserved_byte", begin, can_frame(MAR_CAN_CONFIG + 5, MAR_CAN_PARAM_MIN, 0, 1, 0) },
        { "config_apply_without_begin", sync, can_frame(MAR_CAN_CONFIG + 5, MAR_CAN_PARAM_APPLY, 0, 0, 7) },
        { "status_reserved_flag", sync, can_frame(MAR_CAN_STATUS + 5, 5, 0x20, MAR_STATE_OPERATIONAL, 0) },
        { "loudness_bands_count_0", sync, can_frame(MAR_CAN_BANDS + 5, 0x0C, 40, 41, 0) },
        { "loudness_bands_count_8", sync, can_frame(MAR_CAN_BANDS + 5, 0x8C, 40, 41, 0x2D2C2B2Au) },
        { "loudness_bands_reserved_byte", sync, can_frame(MAR_CAN_BANDS + 5, 0x2C, 40, 41, 1u << 24) },
    };
    for (size_t i = 0; i < sizeof can / sizeof can[0]; i++) {
        static mar_can_rx rx;
        mar_can_rx_init(&rx);
        mar_can_rx_feed(&rx, &can[i].prefix, &m);
        r = mar_can_rx_feed(&rx, &can[i].frame, &m);
        fprintf(f, ",\n  {\"name\": \"%s\", \"link\": \"can\", \"prefix\": ", can[i].name);
        frames(f, &can[i].prefix, 1);
        fprintf(f, ", \"frame\": ");
        frames(f, &can[i].frame, 1);
        fprintf(f, ", \"error\": \"%s\", \"reason\": %d}", error_name(r), mar_reason_of(r));
    }
    fprintf(f, "\n]\n");
    return 0;
}

int main(int argc, char **argv)
{
    static mar_msg ms[32];
    const char *names[32];
    size_t n = messages(ms, names);
    const char *dir = argc > 1 ? argv[1] : ".";
    char path[4096];
    snprintf(path, sizeof path, "%s/serial.json", dir);
    FILE *f = fopen(path, "w");
    if (!f || write_serial(f, ms, names, n) || fclose(f)) {
        perror(path);
        return 1;
    }
    snprintf(path, sizeof path, "%s/can.json", dir);
    f = fopen(path, "w");
    if (!f || write_can(f, ms, names, n) || fclose(f)) {
        perror(path);
        return 1;
    }
    size_t sixty = 0;
    while (strcmp(names[sixty], "setpoints_60_channels") != 0)
        sixty++;
    snprintf(path, sizeof path, "%s/refused.json", dir);
    f = fopen(path, "w");
    if (!f || write_refused(f, &ms[sixty]) || fclose(f)) {
        perror(path);
        return 1;
    }
    return 0;
}
