/* Byte-at-a-time receiver of serial frames: COBS, CRC, then the message.
 *
 * A fixed buffer of MAR_WIRE_MAX bytes, no allocation. Every 0x00 ends a
 * frame, so after any garbage the next frame is read correctly: a frame
 * that grows past the buffer is dropped up to its 0x00 (never a stall, as a
 * corrupted length field would cause), and an empty frame (two 0x00 in a
 * row) is ignored. Counters are uint32 and wrap. */
#ifndef MAR_DEFRAMER_H
#define MAR_DEFRAMER_H

#include <stddef.h>
#include <stdint.h>

#include "mar_proto.h"

typedef struct {
    uint8_t buf[MAR_WIRE_MAX];
    size_t len;                 /* bytes of the frame so far */
    int overflow;               /* the frame outgrew buf: drop it at its 0x00 */
    uint32_t bytes;             /* bytes fed */
    uint32_t frames_ok;         /* messages decoded */
    uint32_t crc_errors;        /* CRC mismatch */
    uint32_t cobs_errors;       /* invalid COBS */
    uint32_t too_long;          /* longer than MAR_WIRE_MAX */
    uint32_t too_short;         /* shorter than header + CRC */
    uint32_t decode_errors;     /* good CRC, refused content (version, type, length, value) */
    uint32_t garbage_bytes;     /* bytes of every refused frame, delimiters not counted */
} mar_deframer;

void mar_deframer_init(mar_deframer *d);

/* Takes one byte. Returns 1 when it ended a good frame (the message is in
 * m), 0 when no frame ended, or MAR_E_* when it ended a refused one; after
 * MAR_E_VERSION, TYPE, LENGTH or VALUE m's type, node and seq hold the
 * header, so a node can answer with a NACK. */
int mar_deframer_push(mar_deframer *d, uint8_t byte, mar_msg *m);

#endif
