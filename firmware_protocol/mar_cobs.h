/* Consistent Overhead Byte Stuffing (Cheshire and Baker, 1999).
 *
 * Encoding removes every 0x00 from a block of bytes, so 0x00 can end each
 * frame on the wire: a receiver that lost its place waits for the next 0x00
 * and is in step again. The cost is one byte per started 254 bytes. */
#ifndef MAR_COBS_H
#define MAR_COBS_H

#include <stddef.h>
#include <stdint.h>

/* Largest encoding of n bytes [bytes], without the 0x00 delimiter. */
#define MAR_COBS_MAX(n) ((n) + (n) / 254u + 1u)

/* Encodes n bytes into out (room for MAR_COBS_MAX(n) bytes; out must not
 * overlap in). Returns the encoded length [bytes]; the result has no 0x00. */
size_t mar_cobs_encode(const uint8_t *in, size_t n, uint8_t *out);

/* Decodes n encoded bytes (no delimiter) into out, which may be in itself
 * (decoding in place is safe: the output never overtakes the input).
 * Returns the decoded length [bytes], or -1 when the input is not the one
 * encoding mar_cobs_encode makes of anything: it is empty, holds a 0x00, a
 * code byte points past its end, or it ends with a block of 254 bytes
 * (code 0xFF) without the final 01; or -2 when cap is too small. */
long mar_cobs_decode(const uint8_t *in, size_t n, uint8_t *out, size_t cap);

#endif
