#include "mar_deframer.h"

#include <string.h>

void mar_deframer_init(mar_deframer *d)
{
    memset(d, 0, sizeof *d);
}

static int refuse(mar_deframer *d, int status, uint32_t *counter)
{
    (*counter)++;
    d->garbage_bytes += (uint32_t)d->len;
    d->len = 0;
    d->overflow = 0;
    return status;
}

int mar_deframer_push(mar_deframer *d, uint8_t byte, mar_msg *m)
{
    d->bytes++;
    if (byte != 0) {
        if (d->len < sizeof d->buf)
            d->buf[d->len] = byte;
        else
            d->overflow = 1;
        d->len++;               /* keeps counting past the buffer, for garbage_bytes */
        return 0;
    }
    if (d->len == 0)
        return 0;
    if (d->overflow)
        return refuse(d, MAR_E_TOOLONG, &d->too_long);
    long n = mar_cobs_decode(d->buf, d->len, d->buf, sizeof d->buf);   /* in place */
    if (n == -2)
        return refuse(d, MAR_E_TOOLONG, &d->too_long);
    if (n < 0)
        return refuse(d, MAR_E_COBS, &d->cobs_errors);
    int r = mar_decode_body(d->buf, (size_t)n, m);
    if (r == MAR_E_SHORT)
        return refuse(d, r, &d->too_short);
    if (r == MAR_E_TOOLONG)
        return refuse(d, r, &d->too_long);
    if (r == MAR_E_CRC)
        return refuse(d, r, &d->crc_errors);
    if (r < 0)
        return refuse(d, r, &d->decode_errors);
    d->len = 0;
    d->frames_ok++;
    return 1;
}
