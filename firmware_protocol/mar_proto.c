#include "mar_proto.h"

#include <float.h>
#include <math.h>
#include <string.h>

#include "mar_bytes.h"

#include "mar_crc.h"

_Static_assert(sizeof(float) == 4, "LOUDNESS carries an IEEE 754 binary32");

static int loudness_ok(float v)
{
    return v >= 0.0f && v <= FLT_MAX;   /* finite, not negative, not NaN */
}

static int state_ok(uint8_t s)
{
    return s == MAR_STATE_BOOT || s == MAR_STATE_STOPPED || s == MAR_STATE_OPERATIONAL
        || s == MAR_STATE_PRE_OPERATIONAL;
}

/* Payload of m at p (room for MAR_PAYLOAD_MAX); its length or MAR_E_*. */
static long encode_payload(const mar_msg *m, uint8_t *p)
{
    switch (m->type) {
    case MAR_MSG_SYNC:
        if (m->node != MAR_BROADCAST)
            return MAR_E_VALUE;
        p[0] = m->sync.poll;
        return 1;
    case MAR_MSG_SETPOINT: {
        size_t n = m->setpoint.n, len = 0;
        if (m->node != MAR_BROADCAST || n == 0)
            return MAR_E_VALUE;
        if (n > MAR_SETPOINT_MAX)
            return MAR_E_RANGE;
        const mar_setpoint_entry *e = m->setpoint.entry;
        for (size_t i = 0; i < n;) {        /* one group per run of consecutive channels */
            size_t k = 1;
            if (e[i].node == MAR_BROADCAST)
                return MAR_E_VALUE;
            while (i + k < n && e[i + k].node == e[i].node && e[i].channel + k <= 255
                   && e[i + k].channel == e[i].channel + k)
                k++;
            if (len + 3 + 4 * k > MAR_PAYLOAD_MAX)
                return MAR_E_RANGE;
            p[len] = e[i].node;
            p[len + 1] = e[i].channel;
            p[len + 2] = (uint8_t)k;
            len += 3;
            for (size_t j = 0; j < k; j++, len += 4)
                mar_put32(p + len, (uint32_t)e[i + j].counts);
            i += k;
        }
        return (long)len;
    }
    case MAR_MSG_ESTOP:
    case MAR_MSG_ESTOP_RELEASE:
        return 0;
    case MAR_MSG_CONFIG: {
        size_t n = m->config.n;
        if (m->node == MAR_BROADCAST)
            return MAR_E_VALUE;
        if (n > MAR_CONFIG_MAX)
            return MAR_E_RANGE;
        mar_put32(p, m->config.tick_period_us);
        mar_put16(p + 4, m->config.watchdog_ticks);
        for (size_t i = 0; i < n; i++) {
            const mar_channel_config *c = &m->config.channel[i];
            uint8_t *q = p + 6 + 17 * i;
            q[0] = c->channel;
            mar_put32(q + 1, (uint32_t)c->min_counts);
            mar_put32(q + 5, (uint32_t)c->max_counts);
            mar_put32(q + 9, c->max_speed);
            mar_put32(q + 13, c->max_accel);
        }
        return (long)(6 + 17 * n);
    }
    case MAR_MSG_STATUS: {
        size_t n = m->status.n;
        if (m->node == MAR_BROADCAST || (m->status.flags & ~MAR_FLAGS_DEFINED)
            || !state_ok(m->status.state))
            return MAR_E_VALUE;
        if (n > MAR_STATUS_MAX)
            return MAR_E_RANGE;
        p[0] = m->status.flags;
        p[1] = m->status.state;
        mar_put16(p + 2, m->status.rejected);
        mar_put16(p + 4, m->status.seq_gaps);
        for (size_t i = 0; i < n; i++)
            mar_put32(p + 6 + 4 * i, (uint32_t)m->status.position[i]);
        return (long)(6 + 4 * n);
    }
    case MAR_MSG_HEARTBEAT:
        if (m->node == MAR_BROADCAST || !state_ok(m->heartbeat.state))
            return MAR_E_VALUE;
        p[0] = m->heartbeat.state;
        return 1;
    case MAR_MSG_LOUDNESS: {
        uint32_t bits;
        size_t k = m->loudness.n_bands;
        if (m->node == MAR_BROADCAST || !loudness_ok(m->loudness.value))
            return MAR_E_VALUE;
        if (k > MAR_BANDS_MAX)
            return MAR_E_RANGE;
        memcpy(&bits, &m->loudness.value, 4);
        mar_put32(p, bits);
        if (k == 0)
            return 4;               /* the one-band form */
        p[4] = (uint8_t)k;
        memcpy(p + 5, m->loudness.band, k);
        return (long)(5 + k);
    }
    case MAR_MSG_NACK:
        if (m->node == MAR_BROADCAST || (m->nack.flags & ~MAR_FLAGS_DEFINED))
            return MAR_E_VALUE;
        mar_put16(p, m->nack.reason);
        p[2] = m->nack.flags;
        p[3] = m->nack.ref_type;
        mar_put32(p + 4, m->nack.ref_seq);
        return 8;
    default:
        return MAR_E_TYPE;
    }
}

long mar_encode_body(const mar_msg *m, uint8_t *body, size_t cap)
{
    uint8_t tmp[MAR_FRAME_MAX];
    long n = encode_payload(m, tmp + MAR_HEADER_BYTES);
    if (n < 0)
        return n;
    size_t len = MAR_HEADER_BYTES + (size_t)n + MAR_CRC_BYTES;
    if (cap < len)
        return MAR_E_SHORT;
    tmp[0] = MAR_PROTO_VERSION;
    tmp[1] = m->type;
    tmp[2] = m->node;
    mar_put32(tmp + 3, m->seq);
    mar_put32(tmp + len - MAR_CRC_BYTES, mar_crc32c(tmp, len - MAR_CRC_BYTES));
    memcpy(body, tmp, len);
    return (long)len;
}

static int decode_payload(const uint8_t *p, size_t len, mar_msg *m)
{
    switch (m->type) {
    case MAR_MSG_SYNC:
        if (len != 1)
            return MAR_E_LENGTH;
        if (m->node != MAR_BROADCAST)
            return MAR_E_VALUE;
        m->sync.poll = p[0];
        return 0;
    case MAR_MSG_SETPOINT: {
        size_t n = 0;
        if (len == 0)
            return MAR_E_LENGTH;
        if (m->node != MAR_BROADCAST)
            return MAR_E_VALUE;
        for (size_t at = 0; at < len;) {
            if (len - at < 3)
                return MAR_E_LENGTH;
            uint8_t node = p[at], first = p[at + 1], k = p[at + 2];
            at += 3;
            if (k == 0 || len - at < 4u * k)
                return MAR_E_LENGTH;
            if (node == MAR_BROADCAST || first + k - 1 > 255)
                return MAR_E_VALUE;
            for (size_t j = 0; j < k; j++, at += 4, n++) {   /* n < 60: the payload is at most 245 bytes */
                m->setpoint.entry[n].node = node;
                m->setpoint.entry[n].channel = (uint8_t)(first + j);
                m->setpoint.entry[n].counts = mar_as_int32(mar_get32(p + at));
            }
        }
        m->setpoint.n = (uint16_t)n;
        return 0;
    }
    case MAR_MSG_ESTOP:
    case MAR_MSG_ESTOP_RELEASE:
        return len == 0 ? 0 : MAR_E_LENGTH;
    case MAR_MSG_CONFIG: {
        if (len < 6 || (len - 6) % 17 != 0)
            return MAR_E_LENGTH;
        if (m->node == MAR_BROADCAST)
            return MAR_E_VALUE;
        size_t n = (len - 6) / 17;
        m->config.tick_period_us = mar_get32(p);
        m->config.watchdog_ticks = mar_get16(p + 4);
        m->config.n = (uint8_t)n;
        for (size_t i = 0; i < n; i++) {
            const uint8_t *q = p + 6 + 17 * i;
            mar_channel_config *c = &m->config.channel[i];
            c->channel = q[0];
            c->min_counts = mar_as_int32(mar_get32(q + 1));
            c->max_counts = mar_as_int32(mar_get32(q + 5));
            c->max_speed = mar_get32(q + 9);
            c->max_accel = mar_get32(q + 13);
        }
        return 0;
    }
    case MAR_MSG_STATUS: {
        if (len < 6 || (len - 6) % 4 != 0)
            return MAR_E_LENGTH;
        if (m->node == MAR_BROADCAST || (p[0] & ~MAR_FLAGS_DEFINED) || !state_ok(p[1]))
            return MAR_E_VALUE;
        size_t n = (len - 6) / 4;
        m->status.flags = p[0];
        m->status.state = p[1];
        m->status.rejected = mar_get16(p + 2);
        m->status.seq_gaps = mar_get16(p + 4);
        m->status.n = (uint8_t)n;
        for (size_t i = 0; i < n; i++)
            m->status.position[i] = mar_as_int32(mar_get32(p + 6 + 4 * i));
        return 0;
    }
    case MAR_MSG_HEARTBEAT:
        if (len != 1)
            return MAR_E_LENGTH;
        if (m->node == MAR_BROADCAST || !state_ok(p[0]))
            return MAR_E_VALUE;
        m->heartbeat.state = p[0];
        return 0;
    case MAR_MSG_LOUDNESS: {
        size_t k = len > 4 ? p[4] : 0;      /* the band count, when there is one */
        if (len != (k ? 5 + k : 4))
            return MAR_E_LENGTH;
        uint32_t bits = mar_get32(p);
        float v;
        memcpy(&v, &bits, 4);
        if (m->node == MAR_BROADCAST || !loudness_ok(v) || k > MAR_BANDS_MAX)
            return MAR_E_VALUE;
        m->loudness.value = v;
        m->loudness.n_bands = (uint8_t)k;
        memcpy(m->loudness.band, p + 5, k);
        return 0;
    }
    case MAR_MSG_NACK:
        if (len != 8)
            return MAR_E_LENGTH;
        if (m->node == MAR_BROADCAST || (p[2] & ~MAR_FLAGS_DEFINED))
            return MAR_E_VALUE;
        m->nack.reason = mar_get16(p);
        m->nack.flags = p[2];
        m->nack.ref_type = p[3];
        m->nack.ref_seq = mar_get32(p + 4);
        return 0;
    default:
        return MAR_E_TYPE;
    }
}

int mar_decode_body(const uint8_t *body, size_t len, mar_msg *m)
{
    if (len < MAR_HEADER_BYTES + MAR_CRC_BYTES)
        return MAR_E_SHORT;
    if (len > MAR_FRAME_MAX)
        return MAR_E_TOOLONG;
    if (mar_get32(body + len - MAR_CRC_BYTES) != mar_crc32c(body, len - MAR_CRC_BYTES))
        return MAR_E_CRC;
    m->type = body[1];
    m->node = body[2];
    m->seq = mar_get32(body + 3);
    if (body[0] != MAR_PROTO_VERSION)
        return MAR_E_VERSION;
    return decode_payload(body + MAR_HEADER_BYTES, len - MAR_HEADER_BYTES - MAR_CRC_BYTES, m);
}

/* COBS of body and the delimiter into wire, if cap holds exactly that. */
static long cobs_out(const uint8_t *body, size_t len, uint8_t *wire, size_t cap)
{
    uint8_t tmp[MAR_WIRE_MAX];
    size_t k = mar_cobs_encode(body, len, tmp);
    tmp[k++] = 0;
    if (cap < k)
        return MAR_E_SHORT;
    memcpy(wire, tmp, k);
    return (long)k;
}

long mar_encode_frame(const mar_msg *m, uint8_t *wire, size_t cap)
{
    uint8_t body[MAR_FRAME_MAX];
    long n = mar_encode_body(m, body, sizeof body);
    if (n < 0)
        return n;
    return cobs_out(body, (size_t)n, wire, cap);
}

int mar_decode_frame(const uint8_t *wire, size_t len, mar_msg *m)
{
    uint8_t body[MAR_FRAME_MAX];
    if (len > 0 && wire[len - 1] == 0)
        len--;
    if (len > MAR_WIRE_MAX - 1)
        return MAR_E_TOOLONG;
    long n = mar_cobs_decode(wire, len, body, sizeof body);
    if (n == -2)
        return MAR_E_TOOLONG;
    if (n < 0)
        return MAR_E_COBS;
    return mar_decode_body(body, (size_t)n, m);
}

/* Ends the SETPOINT frame in body (payload of plen bytes) onto the wire. */
static long flush_setpoints(uint8_t *body, size_t plen, uint8_t *wire, size_t cap)
{
    size_t len = MAR_HEADER_BYTES + plen + MAR_CRC_BYTES;
    mar_put32(body + len - MAR_CRC_BYTES, mar_crc32c(body, len - MAR_CRC_BYTES));
    return cobs_out(body, len, wire, cap);
}

long mar_encode_setpoints(uint32_t tick, const mar_setpoint_entry *entries, size_t n,
                          uint8_t *wire, size_t cap)
{
    uint8_t body[MAR_FRAME_MAX];
    uint8_t *p = body + MAR_HEADER_BYTES;
    size_t used = 0, plen = 0, group = 0;   /* wire bytes; payload bytes; where the open group starts */
    int open = 0;
    body[0] = MAR_PROTO_VERSION;
    body[1] = MAR_MSG_SETPOINT;
    body[2] = MAR_BROADCAST;
    mar_put32(body + 3, tick);
    for (size_t i = 0; i < n; i++) {
        const mar_setpoint_entry *e = &entries[i];
        if (e->node == MAR_BROADCAST)
            return MAR_E_VALUE;
        int extend = open && p[group] == e->node && p[group + 2] < 255
                  && p[group + 1] + p[group + 2] == e->channel;
        if (plen + (extend ? 4u : 7u) > MAR_PAYLOAD_MAX) {
            long r = flush_setpoints(body, plen, wire + used, cap - used);
            if (r < 0)
                return r;
            used += (size_t)r;
            plen = 0;
            extend = 0;
        }
        if (!extend) {
            group = plen;
            p[plen] = e->node;
            p[plen + 1] = e->channel;
            p[plen + 2] = 0;
            plen += 3;
            open = 1;
        }
        p[group + 2]++;
        mar_put32(p + plen, (uint32_t)e->counts);
        plen += 4;
    }
    if (plen > 0) {
        long r = flush_setpoints(body, plen, wire + used, cap - used);
        if (r < 0)
            return r;
        used += (size_t)r;
    }
    return (long)used;
}

size_t mar_setpoints_wire_max(size_t n)
{
    /* a frame closes only when the next entry does not fit, so it holds at
     * least (245 - 6) / 7 = 34 entries, even with one group per entry */
    size_t frames = (n + 33) / 34;
    return frames * MAR_WIRE_MAX;
}

int mar_msg_equal(const mar_msg *a, const mar_msg *b)
{
    if (a->type != b->type || a->node != b->node || a->seq != b->seq)
        return 0;
    switch (a->type) {
    case MAR_MSG_SYNC:
        return a->sync.poll == b->sync.poll;
    case MAR_MSG_SETPOINT:
        if (a->setpoint.n != b->setpoint.n)
            return 0;
        for (size_t i = 0; i < a->setpoint.n; i++) {
            const mar_setpoint_entry *x = &a->setpoint.entry[i], *y = &b->setpoint.entry[i];
            if (x->node != y->node || x->channel != y->channel || x->counts != y->counts)
                return 0;
        }
        return 1;
    case MAR_MSG_ESTOP:
    case MAR_MSG_ESTOP_RELEASE:
        return 1;
    case MAR_MSG_CONFIG:
        if (a->config.tick_period_us != b->config.tick_period_us
            || a->config.watchdog_ticks != b->config.watchdog_ticks || a->config.n != b->config.n)
            return 0;
        for (size_t i = 0; i < a->config.n; i++) {
            const mar_channel_config *x = &a->config.channel[i], *y = &b->config.channel[i];
            if (x->channel != y->channel || x->min_counts != y->min_counts
                || x->max_counts != y->max_counts || x->max_speed != y->max_speed
                || x->max_accel != y->max_accel)
                return 0;
        }
        return 1;
    case MAR_MSG_STATUS:
        if (a->status.flags != b->status.flags || a->status.state != b->status.state
            || a->status.rejected != b->status.rejected || a->status.seq_gaps != b->status.seq_gaps
            || a->status.n != b->status.n)
            return 0;
        for (size_t i = 0; i < a->status.n; i++)
            if (a->status.position[i] != b->status.position[i])
                return 0;
        return 1;
    case MAR_MSG_HEARTBEAT:
        return a->heartbeat.state == b->heartbeat.state;
    case MAR_MSG_LOUDNESS:
        return memcmp(&a->loudness.value, &b->loudness.value, 4) == 0
            && a->loudness.n_bands == b->loudness.n_bands
            && memcmp(a->loudness.band, b->loudness.band, a->loudness.n_bands) == 0;
    case MAR_MSG_NACK:
        return a->nack.reason == b->nack.reason && a->nack.flags == b->nack.flags
            && a->nack.ref_type == b->nack.ref_type && a->nack.ref_seq == b->nack.ref_seq;
    default:
        return 0;
    }
}

int mar_config_reason(const mar_msg *m)
{
    if (m->config.tick_period_us == 0 || m->config.watchdog_ticks == 0)
        return MAR_REASON_BAD_CONFIG;
    for (size_t i = 0; i < m->config.n; i++) {
        const mar_channel_config *c = &m->config.channel[i];
        if (c->min_counts > c->max_counts || c->max_speed == 0 || c->max_accel == 0)
            return MAR_REASON_BAD_CONFIG;
        for (size_t j = 0; j < i; j++)
            if (m->config.channel[j].channel == c->channel)
                return MAR_REASON_BAD_CONFIG;
    }
    return MAR_REASON_ACCEPTED;
}

int mar_band_code(float db)
{
    if (db != db || db > FLT_MAX)
        return MAR_E_VALUE;             /* NaN, +infinity */
    if (db >= MAR_BAND_TOP_DB)
        return 0;
    float steps = (MAR_BAND_TOP_DB - db) * MAR_BAND_STEPS_PER_DB;   /* > 0, or +infinity */
    if (!(steps < MAR_BAND_SILENT - 0.5f))
        return MAR_BAND_SILENT;
    return (int)(steps + 0.5f);
}

float mar_band_db(uint8_t code)
{
    if (code == MAR_BAND_SILENT)
        return -INFINITY;
    return MAR_BAND_TOP_DB - (float)code / MAR_BAND_STEPS_PER_DB;
}

int mar_reason_of(int status)
{
    switch (status) {
    case 0:
        return MAR_REASON_ACCEPTED;
    case MAR_E_VERSION:
        return MAR_REASON_BAD_VERSION;
    case MAR_E_TYPE:
        return MAR_REASON_BAD_TYPE;
    case MAR_E_LENGTH:
        return MAR_REASON_BAD_LENGTH;
    case MAR_E_STALE:
        return MAR_REASON_STALE;
    case MAR_E_INCOMPLETE:
        return MAR_REASON_CONFIG_INCOMPLETE;
    default:
        return MAR_REASON_BAD_VALUE;
    }
}
