/* Little-endian fields of the protocol, read and written byte by byte: no
 * alignment or endianness assumptions, no implementation-defined casts, so
 * the same code runs on the host and on a node's microcontroller. */
#ifndef MAR_BYTES_H
#define MAR_BYTES_H

#include <stdint.h>

static inline void mar_put16(uint8_t *p, uint16_t v)
{
    p[0] = (uint8_t)v;
    p[1] = (uint8_t)(v >> 8);
}

static inline void mar_put32(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)v;
    p[1] = (uint8_t)(v >> 8);
    p[2] = (uint8_t)(v >> 16);
    p[3] = (uint8_t)(v >> 24);
}

static inline uint16_t mar_get16(const uint8_t *p)
{
    return (uint16_t)((unsigned)p[0] | (unsigned)p[1] << 8);   /* no int overflow where int is 16 bits */
}

static inline uint32_t mar_get32(const uint8_t *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

/* Two's complement without implementation-defined conversions. */
static inline int32_t mar_as_int32(uint32_t u)
{
    return u <= 0x7FFFFFFFu ? (int32_t)u : (int32_t)(u - 0x80000000u) - INT32_MAX - 1;
}

#endif
