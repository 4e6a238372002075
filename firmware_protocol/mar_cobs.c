#include "mar_cobs.h"

size_t mar_cobs_encode(const uint8_t *in, size_t n, uint8_t *out)
{
    size_t code_at = 0, o = 1;   /* where the pending code byte goes; next output */
    uint8_t code = 1;            /* 1 + data bytes in the current block */
    for (size_t i = 0; i < n; i++) {
        if (in[i] != 0) {
            out[o++] = in[i];
            code++;
        }
        if (in[i] == 0 || code == 0xFF) {
            out[code_at] = code;
            code_at = o++;
            code = 1;
        }
    }
    out[code_at] = code;
    return o;
}

long mar_cobs_decode(const uint8_t *in, size_t n, uint8_t *out, size_t cap)
{
    size_t i = 0, o = 0;
    if (n == 0)                 /* the encoding of nothing is 01 */
        return -1;
    while (i < n) {
        uint8_t code = in[i++];
        if (code == 0)
            return -1;
        size_t run = (size_t)code - 1;
        if (run > n - i)
            return -1;
        if (run > cap - o)
            return -2;
        for (size_t k = 0; k < run; k++) {
            if (in[i] == 0)
                return -1;
            out[o++] = in[i++];
        }
        /* one encoding per block: a run of 254 bytes (0xFF) is always followed
         * by another block, 01 at the end (the "optimised" COBS leaves it out) */
        if (code == 0xFF && i == n)
            return -1;
        /* a block shorter than 254 bytes stands for a 0x00, except the last */
        if (code != 0xFF && i < n) {
            if (o == cap)
                return -2;
            out[o++] = 0;
        }
    }
    return (long)o;
}
