#include "mar_proto_can.h"

#include <float.h>
#include <string.h>

#include "mar_bytes.h"

static int node_ok(uint8_t node)
{
    return node >= 1 && node <= MAR_CAN_NODE_MAX;
}

static int state_ok(uint8_t s)
{
    return s == MAR_STATE_BOOT || s == MAR_STATE_STOPPED || s == MAR_STATE_OPERATIONAL
        || s == MAR_STATE_PRE_OPERATIONAL;
}

int32_t mar_can_saturate(int32_t counts)
{
    return counts > MAR_CAN_COUNTS_MAX ? MAR_CAN_COUNTS_MAX
         : counts < -MAR_CAN_COUNTS_MAX ? -MAR_CAN_COUNTS_MAX : counts;
}

/* A PDO: 4-bit counter, then three int20 fields, as one little-endian uint64. */
static void put_pdo(mar_can_frame *f, uint16_t id, uint32_t tick, const int32_t v[3])
{
    uint64_t w = tick & 0xFu;
    for (int k = 0; k < 3; k++)
        w |= (uint64_t)((uint32_t)v[k] & 0xFFFFFu) << (4 + 20 * k);
    f->id = id;
    f->dlc = 8;
    for (int i = 0; i < 8; i++)
        f->data[i] = (uint8_t)(w >> (8 * i));
}

static uint8_t get_pdo(const mar_can_frame *f, int32_t v[3])
{
    uint64_t w = 0;
    for (int i = 0; i < 8; i++)
        w |= (uint64_t)f->data[i] << (8 * i);
    for (int k = 0; k < 3; k++) {
        uint32_t u = (uint32_t)(w >> (4 + 20 * k)) & 0xFFFFFu;
        v[k] = (u & 0x80000u) ? (int32_t)u - 0x100000 : (int32_t)u;
    }
    return (uint8_t)(w & 0xFu);
}

static void frame(mar_can_frame *f, uint16_t id, uint8_t dlc)
{
    f->id = id;
    f->dlc = dlc;
    memset(f->data, 0, sizeof f->data);
}

static long setpoints(uint32_t tick, const mar_setpoint_entry *e, size_t n,
                      mar_can_frame *out, size_t cap, int strict)
{
    size_t count = 0;
    for (size_t i = 0; i < n;) {
        uint8_t node = e[i].node, pdo = (uint8_t)(e[i].channel / MAR_CAN_PER_PDO);
        int32_t v[3] = { MAR_CAN_COUNTS_NONE, MAR_CAN_COUNTS_NONE, MAR_CAN_COUNTS_NONE };
        if (count == cap)
            return MAR_E_SHORT;
        /* the following entries of the same node and PDO share its frame */
        for (; i < n && e[i].node == node && e[i].channel / MAR_CAN_PER_PDO == pdo; i++) {
            if (!node_ok(node) || e[i].channel >= MAR_CAN_CHANNELS)
                return MAR_E_VALUE;
            int32_t c = e[i].counts;
            if (strict && (c > MAR_CAN_COUNTS_MAX || c < -MAR_CAN_COUNTS_MAX))
                return MAR_E_RANGE;
            v[e[i].channel % MAR_CAN_PER_PDO] = mar_can_saturate(c);
        }
        put_pdo(&out[count++], (uint16_t)(MAR_CAN_SETPOINT + 0x100u * pdo + node), tick, v);
    }
    return (long)count;
}

long mar_can_encode_setpoints(uint32_t tick, const mar_setpoint_entry *entries, size_t n,
                              mar_can_frame *out, size_t cap)
{
    return setpoints(tick, entries, n, out, cap, 0);
}

size_t mar_can_setpoints_max(size_t n)
{
    return n;
}

long mar_can_encode(const mar_msg *m, mar_can_frame *out, size_t cap)
{
    size_t need;
    switch (m->type) {
    case MAR_MSG_SETPOINT:
        if (m->node != MAR_BROADCAST || m->setpoint.n == 0 || m->setpoint.n > MAR_SETPOINT_MAX)
            return MAR_E_VALUE;
        return setpoints(m->seq, m->setpoint.entry, m->setpoint.n, out, cap, 1);
    case MAR_MSG_STATUS:
        need = 1 + (m->status.n + 2u) / 3u;
        break;
    case MAR_MSG_CONFIG:
        need = 3 + 4u * m->config.n;
        break;
    case MAR_MSG_LOUDNESS:
        need = m->loudness.n_bands ? 2 : 1;
        break;
    default:
        need = 1;
    }
    if (cap < need)
        return MAR_E_SHORT;
    switch (m->type) {
    case MAR_MSG_SYNC:
        if (m->node != MAR_BROADCAST || m->sync.poll != MAR_BROADCAST)
            return MAR_E_VALUE;
        frame(out, MAR_CAN_SYNC, 1);
        out->data[0] = (uint8_t)m->seq;
        return 1;
    case MAR_MSG_ESTOP:
    case MAR_MSG_ESTOP_RELEASE:
        if (!node_ok(m->node) && m->node != MAR_BROADCAST)
            return MAR_E_VALUE;
        frame(out, m->type == MAR_MSG_ESTOP ? MAR_CAN_ESTOP : MAR_CAN_ESTOP_RELEASE, 1);
        out->data[0] = m->node;
        return 1;
    case MAR_MSG_CONFIG: {
        size_t n = m->config.n, k = 0;
        if (!node_ok(m->node) || n > MAR_CAN_CHANNELS)
            return MAR_E_VALUE;
        uint16_t id = (uint16_t)(MAR_CAN_CONFIG + m->node);
        frame(&out[k], id, 8);
        out[k].data[0] = MAR_CAN_PARAM_BEGIN;
        out[k].data[1] = 0xFF;
        mar_put32(out[k++].data + 4, m->config.tick_period_us);
        frame(&out[k], id, 8);
        out[k].data[0] = MAR_CAN_PARAM_WATCHDOG;
        out[k].data[1] = 0xFF;
        mar_put32(out[k++].data + 4, m->config.watchdog_ticks);
        for (size_t i = 0; i < n; i++) {
            const mar_channel_config *c = &m->config.channel[i];
            uint32_t value[4] = { (uint32_t)c->min_counts, (uint32_t)c->max_counts, c->max_speed,
                                  c->max_accel };
            if (c->channel >= MAR_CAN_CHANNELS)
                return MAR_E_VALUE;
            for (size_t j = 0; j < i; j++)   /* the receiver joins by channel */
                if (m->config.channel[j].channel == c->channel)
                    return MAR_E_VALUE;
            for (int p = 0; p < 4; p++) {
                frame(&out[k], id, 8);
                out[k].data[0] = (uint8_t)(MAR_CAN_PARAM_MIN + p);
                out[k].data[1] = c->channel;
                mar_put32(out[k++].data + 4, value[p]);
            }
        }
        frame(&out[k], id, 8);
        out[k].data[0] = MAR_CAN_PARAM_APPLY;
        out[k].data[1] = (uint8_t)n;
        mar_put32(out[k++].data + 4, m->seq);
        return (long)k;
    }
    case MAR_MSG_STATUS: {
        size_t n = m->status.n;
        if (!node_ok(m->node) || n > MAR_CAN_CHANNELS || (m->status.flags & ~MAR_FLAGS_DEFINED)
            || !state_ok(m->status.state))
            return MAR_E_VALUE;
        for (size_t i = 0; i < n; i++)
            if (m->status.position[i] > MAR_CAN_COUNTS_MAX || m->status.position[i] < -MAR_CAN_COUNTS_MAX)
                return MAR_E_RANGE;
        frame(out, (uint16_t)(MAR_CAN_STATUS + m->node), 8);
        out->data[0] = (uint8_t)m->seq;
        out->data[1] = m->status.flags;
        out->data[2] = m->status.state;
        out->data[3] = (uint8_t)n;
        mar_put16(out->data + 4, m->status.rejected);
        mar_put16(out->data + 6, m->status.seq_gaps);
        for (size_t pdo = 0; 3 * pdo < n; pdo++) {
            int32_t v[3];
            for (size_t k = 0; k < 3; k++)
                v[k] = 3 * pdo + k < n ? m->status.position[3 * pdo + k] : MAR_CAN_COUNTS_NONE;
            put_pdo(&out[1 + pdo], (uint16_t)(MAR_CAN_POSITION + 0x100u * pdo + m->node), m->seq, v);
        }
        return (long)need;
    }
    case MAR_MSG_HEARTBEAT:
        if (!node_ok(m->node) || !state_ok(m->heartbeat.state))
            return MAR_E_VALUE;
        frame(out, (uint16_t)(MAR_CAN_HEARTBEAT + m->node), 1);
        out->data[0] = m->heartbeat.state;
        return 1;
    case MAR_MSG_LOUDNESS: {
        uint32_t bits;
        float v = m->loudness.value;
        size_t k = m->loudness.n_bands;
        if (!node_ok(m->node) || !(v >= 0.0f && v <= FLT_MAX))
            return MAR_E_VALUE;
        if (k > MAR_CAN_BANDS_MAX)
            return MAR_E_RANGE;
        if (k > 0) {            /* the bands go first: the LOUDNESS frame completes the message */
            frame(out, (uint16_t)(MAR_CAN_BANDS + m->node), 8);
            out->data[0] = (uint8_t)((m->seq & 0xFu) | (k << 4));
            memcpy(out->data + 1, m->loudness.band, k);
            out++;
        }
        memcpy(&bits, &v, 4);
        frame(out, (uint16_t)(MAR_CAN_LOUDNESS + m->node), 8);
        mar_put32(out->data, m->seq);
        mar_put32(out->data + 4, bits);
        return (long)need;
    }
    case MAR_MSG_NACK:
        if (!node_ok(m->node) || (m->nack.flags & ~MAR_FLAGS_DEFINED))
            return MAR_E_VALUE;
        frame(out, (uint16_t)(MAR_CAN_EMCY + m->node), 8);
        mar_put16(out->data, m->nack.reason);
        out->data[2] = m->nack.flags;
        out->data[3] = m->nack.ref_type;
        mar_put32(out->data + 4, m->nack.ref_seq);
        return 1;
    default:
        return MAR_E_TYPE;
    }
}

void mar_can_rx_init(mar_can_rx *rx)
{
    memset(rx, 0, sizeof *rx);
}

/* The full tick a counter of `bits` bits stands for, at or before the last SYNC. */
static uint32_t tick_before(const mar_can_rx *rx, uint32_t counter, uint32_t mask)
{
    if (!rx->have_tick)
        return counter;
    return rx->tick - ((rx->tick - counter) & mask);
}

static int emit_status(mar_can_join *j, uint8_t node, const mar_can_rx *rx, mar_msg *m)
{
    size_t pdos = (j->n + 2u) / 3u;
    if (!(j->parts & 1u) || (j->parts >> 1) != (1u << pdos) - 1u)
        return 0;
    m->type = MAR_MSG_STATUS;
    m->node = node;
    m->seq = tick_before(rx, j->tick8, 0xFFu);
    m->status.flags = j->flags;
    m->status.state = j->state;
    m->status.rejected = j->rejected;
    m->status.seq_gaps = j->seq_gaps;
    m->status.n = j->n;
    memcpy(m->status.position, j->position, j->n * sizeof j->position[0]);
    j->parts = 0;
    return 1;
}

/* A frame of node's status: starts over when its counter is not the one held. */
static void join_counter(mar_can_join *j, uint8_t counter)
{
    if (j->parts && j->counter != counter)
        j->parts = 0;
    j->counter = counter;
}

static int feed_config(mar_can_rx *rx, uint8_t node, const uint8_t *d, mar_msg *m)
{
    uint8_t param = d[0], channel = d[1];
    uint32_t value = mar_get32(d + 4);
    if (d[2] != 0 || d[3] != 0)
        return MAR_E_VALUE;
    if (param == MAR_CAN_PARAM_BEGIN) {
        if (channel != 0xFF)
            return MAR_E_VALUE;
        memset(&rx->config, 0, sizeof rx->config);
        memset(rx->config_have, 0, sizeof rx->config_have);
        rx->config.type = MAR_MSG_CONFIG;
        rx->config.node = node;
        rx->config.config.tick_period_us = value;
        rx->config_open = 1;
        rx->config_watchdog = 0;
        return 0;
    }
    if (param != MAR_CAN_PARAM_WATCHDOG && param != MAR_CAN_PARAM_APPLY
        && (param < MAR_CAN_PARAM_MIN || param > MAR_CAN_PARAM_ACCEL))
        return MAR_E_VALUE;
    if (!rx->config_open || rx->config.node != node) {   /* no BEGIN, or another node's */
        rx->config_open = 0;
        return MAR_E_INCOMPLETE;
    }
    if (param == MAR_CAN_PARAM_WATCHDOG) {
        if (channel != 0xFF || value > 0xFFFFu)
            return MAR_E_VALUE;
        rx->config.config.watchdog_ticks = (uint16_t)value;
        rx->config_watchdog = 1;
        return 0;
    }
    size_t n = rx->config.config.n;
    if (param == MAR_CAN_PARAM_APPLY) {
        rx->config_open = 0;
        int whole = rx->config_watchdog && channel == n;
        for (size_t i = 0; i < n; i++)
            whole = whole && rx->config_have[i] == 0xF;
        if (!whole)
            return MAR_E_INCOMPLETE;
        rx->config.seq = value;
        *m = rx->config;
        return 1;
    }
    if (channel >= MAR_CAN_CHANNELS)
        return MAR_E_VALUE;
    size_t i = 0;
    while (i < n && rx->config.config.channel[i].channel != channel)
        i++;
    if (i == n) {               /* first parameter of this channel; at most 9 distinct */
        rx->config.config.channel[i].channel = channel;
        rx->config.config.n = (uint8_t)(n + 1);
    }
    mar_channel_config *c = &rx->config.config.channel[i];
    switch (param) {
    case MAR_CAN_PARAM_MIN: c->min_counts = mar_as_int32(value); break;
    case MAR_CAN_PARAM_MAX: c->max_counts = mar_as_int32(value); break;
    case MAR_CAN_PARAM_SPEED: c->max_speed = value; break;
    default: c->max_accel = value; break;
    }
    rx->config_have[i] |= (uint8_t)(1u << (param - MAR_CAN_PARAM_MIN));
    return 0;
}

int mar_can_rx_feed(mar_can_rx *rx, const mar_can_frame *f, mar_msg *m)
{
    uint16_t id = f->id;
    const uint8_t *d = f->data;
    if (f->dlc > 8 || id > 0x7FF)
        return MAR_E_ID;
    if (id == MAR_CAN_ESTOP || id == MAR_CAN_ESTOP_RELEASE) {
        if (f->dlc != 1)
            return MAR_E_LENGTH;
        if (!node_ok(d[0]) && d[0] != MAR_BROADCAST)
            return MAR_E_VALUE;
        m->type = id == MAR_CAN_ESTOP ? MAR_MSG_ESTOP : MAR_MSG_ESTOP_RELEASE;
        m->node = d[0];
        m->seq = 0;
        return 1;
    }
    if (id == MAR_CAN_SYNC) {
        if (f->dlc != 1)
            return MAR_E_LENGTH;
        rx->tick = rx->have_tick ? rx->tick + (uint8_t)(d[0] - (uint8_t)rx->tick) : d[0];
        rx->have_tick = 1;
        m->type = MAR_MSG_SYNC;
        m->node = MAR_BROADCAST;
        m->seq = rx->tick;
        m->sync.poll = MAR_BROADCAST;
        return 1;
    }
    uint8_t node = (uint8_t)(id & 0x7Fu);
    uint16_t function = id & 0x780u;
    if (!node_ok(node))
        return MAR_E_ID;
    uint8_t want = function == MAR_CAN_HEARTBEAT ? 1 : 8;
    switch (function) {
    case MAR_CAN_EMCY: case MAR_CAN_STATUS: case MAR_CAN_HEARTBEAT: case MAR_CAN_LOUDNESS:
    case MAR_CAN_BANDS: case MAR_CAN_CONFIG:
    case MAR_CAN_SETPOINT: case MAR_CAN_SETPOINT + 0x100u: case MAR_CAN_SETPOINT + 0x200u:
    case MAR_CAN_POSITION: case MAR_CAN_POSITION + 0x100u: case MAR_CAN_POSITION + 0x200u:
        break;
    default:
        return MAR_E_ID;
    }
    if (f->dlc != want)
        return MAR_E_LENGTH;
    m->node = node;
    m->seq = 0;
    switch (function) {
    case MAR_CAN_EMCY:
        if (d[2] & ~MAR_FLAGS_DEFINED)
            return MAR_E_VALUE;
        m->type = MAR_MSG_NACK;
        m->nack.reason = mar_get16(d);
        m->nack.flags = d[2];
        m->nack.ref_type = d[3];
        m->nack.ref_seq = mar_get32(d + 4);
        return 1;
    case MAR_CAN_HEARTBEAT:
        if (!state_ok(d[0]))
            return MAR_E_VALUE;
        m->type = MAR_MSG_HEARTBEAT;
        m->heartbeat.state = d[0];
        return 1;
    case MAR_CAN_LOUDNESS: {
        uint32_t bits = mar_get32(d + 4);
        float v;
        memcpy(&v, &bits, 4);
        mar_can_join *j = &rx->join[node];
        uint8_t held = j->n_bands;
        j->n_bands = 0;         /* bands are for the LOUDNESS right after them only */
        if (!(v >= 0.0f && v <= FLT_MAX))
            return MAR_E_VALUE;
        m->type = MAR_MSG_LOUDNESS;
        m->seq = mar_get32(d);
        m->loudness.value = v;
        m->loudness.n_bands = held && j->bands_counter == (m->seq & 0xFu) ? held : 0;
        memcpy(m->loudness.band, j->band, m->loudness.n_bands);
        return 1;
    }
    case MAR_CAN_BANDS: {
        mar_can_join *j = &rx->join[node];
        uint8_t k = d[0] >> 4;
        j->n_bands = 0;
        if (k == 0 || k > MAR_CAN_BANDS_MAX)
            return MAR_E_VALUE;
        for (size_t i = 1u + k; i < 8; i++)
            if (d[i] != 0)
                return MAR_E_VALUE;     /* reserved bytes */
        j->n_bands = k;
        j->bands_counter = d[0] & 0xFu;
        memcpy(j->band, d + 1, k);
        return 0;
    }
    case MAR_CAN_CONFIG:
        return feed_config(rx, node, d, m);
    case MAR_CAN_STATUS: {
        mar_can_join *j = &rx->join[node];
        if ((d[1] & ~MAR_FLAGS_DEFINED) || !state_ok(d[2]) || d[3] > MAR_CAN_CHANNELS)
            return MAR_E_VALUE;
        join_counter(j, d[0] & 0xFu);
        j->parts |= 1u;
        j->tick8 = d[0];
        j->flags = d[1];
        j->state = d[2];
        j->n = d[3];
        j->rejected = mar_get16(d + 4);
        j->seq_gaps = mar_get16(d + 6);
        for (size_t k = 0; k < MAR_CAN_CHANNELS; k++)   /* PDOs held must agree with n */
            if ((j->parts >> (1 + k / 3)) & 1u) {
                int32_t v = j->position[k];
                if ((k < j->n) == (v == MAR_CAN_COUNTS_NONE)) {
                    j->parts = 0;
                    return MAR_E_VALUE;
                }
            }
        return emit_status(j, node, rx, m);
    }
    default:
        break;
    }
    /* the PDOs: setpoints (host to node) and actual positions (node to host) */
    int32_t v[3];
    uint8_t counter = get_pdo(f, v);
    uint8_t pdo = (uint8_t)((function - (function & 0x80u ? MAR_CAN_POSITION : MAR_CAN_SETPOINT)) >> 8);
    if (function & 0x80u) {
        mar_can_join *j = &rx->join[node];
        join_counter(j, counter);
        if (j->parts & 1u) {    /* header held: the fields must match its channel count */
            for (size_t k = 0; k < 3; k++)
                if ((3u * pdo + k < j->n) == (v[k] == MAR_CAN_COUNTS_NONE)) {
                    j->parts = 0;
                    return MAR_E_VALUE;
                }
        }
        memcpy(&j->position[3 * pdo], v, sizeof v);
        j->parts |= (uint8_t)(1u << (1 + pdo));
        return emit_status(j, node, rx, m);
    }
    if (!rx->have_tick || counter != (rx->tick & 0xFu))
        return MAR_E_STALE;
    m->type = MAR_MSG_SETPOINT;
    m->node = MAR_BROADCAST;
    m->seq = rx->tick;
    uint16_t n = 0;
    for (uint8_t k = 0; k < 3; k++) {
        if (v[k] == MAR_CAN_COUNTS_NONE)
            continue;
        m->setpoint.entry[n].node = node;
        m->setpoint.entry[n].channel = (uint8_t)(3 * pdo + k);
        m->setpoint.entry[n].counts = v[k];
        n++;
    }
    if (n == 0)
        return MAR_E_VALUE;
    m->setpoint.n = n;
    return 1;
}
