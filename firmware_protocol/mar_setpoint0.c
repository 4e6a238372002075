#include "mar_setpoint0.h"

static uint16_t fletcher16(const uint8_t *p, size_t len)
{
    uint32_t a = 0, b = 0;
    for (size_t i = 0; i < len; i++) {
        a = (a + p[i]) % 255u;
        b = (b + a) % 255u;
    }
    return (uint16_t)(a | (b << 8));
}

static void put32(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)v;
    p[1] = (uint8_t)(v >> 8);
    p[2] = (uint8_t)(v >> 16);
    p[3] = (uint8_t)(v >> 24);
}

static uint32_t get32(const uint8_t *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

size_t mar_sp0_size(size_t n)
{
    return MAR_SP0_HEADER + MAR_SP0_ENTRY * n + 2;
}

long mar_sp0_encode(uint32_t tick, const mar_sp0_entry *entries, size_t n,
                    uint8_t *buf, size_t cap)
{
    if (n == 0 || n > MAR_SP0_MAX_ENTRIES)
        return MAR_SP0_ECOUNT;
    size_t size = mar_sp0_size(n);
    if (cap < size)
        return MAR_SP0_ESHORT;
    buf[0] = MAR_SP0_MAGIC0;
    buf[1] = MAR_SP0_MAGIC1;
    buf[2] = MAR_SP0_VERSION;
    buf[3] = (uint8_t)n;
    put32(buf + 4, tick);
    for (size_t i = 0; i < n; i++) {
        uint8_t *e = buf + MAR_SP0_HEADER + MAR_SP0_ENTRY * i;
        e[0] = entries[i].node;
        e[1] = entries[i].channel;
        put32(e + 2, (uint32_t)entries[i].counts);
    }
    uint16_t check = fletcher16(buf, size - 2);
    buf[size - 2] = (uint8_t)check;
    buf[size - 1] = (uint8_t)(check >> 8);
    return (long)size;
}

long mar_sp0_decode(const uint8_t *buf, size_t len, uint32_t *tick,
                    mar_sp0_entry *entries, size_t cap, size_t *n)
{
    if (len < MAR_SP0_HEADER)
        return MAR_SP0_ESHORT;
    if (buf[0] != MAR_SP0_MAGIC0 || buf[1] != MAR_SP0_MAGIC1 || buf[2] != MAR_SP0_VERSION)
        return MAR_SP0_EMAGIC;
    size_t count = buf[3];
    if (count == 0)
        return MAR_SP0_ECOUNT;
    size_t size = mar_sp0_size(count);
    if (len < size)
        return MAR_SP0_ESHORT;
    uint16_t check = (uint16_t)(buf[size - 2] | buf[size - 1] << 8);
    if (check != fletcher16(buf, size - 2))
        return MAR_SP0_ECHECK;
    *tick = get32(buf + 4);
    *n = count;
    for (size_t i = 0; i < count && i < cap; i++) {
        const uint8_t *e = buf + MAR_SP0_HEADER + MAR_SP0_ENTRY * i;
        entries[i].node = e[0];
        entries[i].channel = e[1];
        entries[i].counts = (int32_t)get32(e + 2);
    }
    return (long)size;
}
