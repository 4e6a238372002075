/* Interim setpoint record, protocol version 0.
 *
 * The wire format until the versioned protocol (firmware_protocol/SPEC.md,
 * the protocol issue) replaces it. Plain C11, no allocation, no Python:
 * compiles for a servo node's microcontroller as it is.
 *
 * Layout, all integers little-endian:
 *   offset  size  field
 *   0       2     magic 0x4D 0x53 ("MS")
 *   2       1     version, 0
 *   3       1     entry count n (1..255)
 *   4       4     tick counter, uint32, wraps
 *   8       6*n   entries: node (u8), channel (u8), counts (int32)
 *   8+6n    2     Fletcher-16 over bytes 0 .. 8+6n-1 (sum1 first)
 */
#ifndef MAR_SETPOINT0_H
#define MAR_SETPOINT0_H

#include <stddef.h>
#include <stdint.h>

#define MAR_SP0_MAGIC0 0x4D
#define MAR_SP0_MAGIC1 0x53
#define MAR_SP0_VERSION 0
#define MAR_SP0_HEADER 8          /* [bytes] */
#define MAR_SP0_ENTRY 6           /* [bytes] */
#define MAR_SP0_MAX_ENTRIES 255

/* decoder and encoder results (negative = error) */
#define MAR_SP0_ESHORT (-1)       /* buffer too small, or record truncated */
#define MAR_SP0_EMAGIC (-2)       /* not a version-0 record */
#define MAR_SP0_ECOUNT (-3)       /* entry count 0 or above the maximum */
#define MAR_SP0_ECHECK (-4)       /* checksum mismatch */

typedef struct {
    uint8_t node;                 /* servo node address */
    uint8_t channel;              /* axis channel on that node */
    int32_t counts;               /* setpoint [device counts] */
} mar_sp0_entry;

/* Bytes of a record with n entries. */
size_t mar_sp0_size(size_t n);

/* Writes one record; returns its size [bytes] or a negative error. */
long mar_sp0_encode(uint32_t tick, const mar_sp0_entry *entries, size_t n,
                    uint8_t *buf, size_t cap);

/* Reads one record from the start of buf; returns the bytes it used or a
 * negative error. At most cap entries are written to entries. */
long mar_sp0_decode(const uint8_t *buf, size_t len, uint32_t *tick,
                    mar_sp0_entry *entries, size_t cap, size_t *n);

#endif
