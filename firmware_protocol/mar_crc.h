/* CRC-32C (Castagnoli), the check over every version-1 frame.
 *
 * Parameters (the "CRC-32/ISCSI" of the CRC catalogue): polynomial
 * 0x1EDC6F41 (0x82F63B78 reflected), init 0xFFFFFFFF, input and output
 * reflected, final XOR 0xFFFFFFFF; check value of "123456789" is 0xE3069283.
 * Why this polynomial and not CRC-16 or the Ethernet CRC-32: SPEC.md, "Check". */
#ifndef MAR_CRC_H
#define MAR_CRC_H

#include <stddef.h>
#include <stdint.h>

#define MAR_CRC32C_CHECK 0xE3069283u   /* crc of the ASCII bytes "123456789" */

/* CRC-32C of len bytes. */
uint32_t mar_crc32c(const uint8_t *data, size_t len);

/* Incremental form: crc = mar_crc32c_update(0, a, n); crc = mar_crc32c_update(crc, b, m)
 * equals mar_crc32c of a followed by b. */
uint32_t mar_crc32c_update(uint32_t crc, const uint8_t *data, size_t len);

#endif
