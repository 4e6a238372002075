/* Servo protocol version 1 on CAN: 11-bit identifiers in the manner of
 * CANopen's predefined connection set (SPEC.md, "CAN mapping").
 *
 *   id            from  DLC  content
 *   0x001         host  1    ESTOP: node (0xFF every node)
 *   0x002         host  1    ESTOP_RELEASE: node (0xFF every node)
 *   0x080         host  1    SYNC: tick & 0xFF
 *   0x080 + node  node  8    NACK, as CANopen EMCY: reason u16, flags, ref type, ref seq u32
 *   0x180 + node  node  8    STATUS header: tick & 0xFF, flags, state, channels, rejected u16, seq gaps u16
 *   0x200 + node  host  8    SETPOINT channels 0..2   } counter (tick & 0xF) in bits 0..3,
 *   0x300 + node  host  8    SETPOINT channels 3..5   } then three int20 counts in bits
 *   0x400 + node  host  8    SETPOINT channels 6..8   } 4..23, 24..43, 44..63
 *   0x280 + node  node  8    STATUS positions 0..2    } same layout, actual positions
 *   0x380 + node  node  8    STATUS positions 3..5    }
 *   0x480 + node  node  8    STATUS positions 6..8    }
 *   0x580 + node  node  8    LOUDNESS bands: frame counter & 0xF (bits 0..3), band count k 1..7
 *                            (bits 4..7), k band codes, 0 to the end; just before its LOUDNESS
 *   0x600 + node  host  8    CONFIG, one parameter per frame: param, channel, 0, 0, value u32/i32
 *   0x680 + node  node  8    LOUDNESS: frame counter u32, loudness float32
 *   0x700 + node  node  1    HEARTBEAT: state
 *
 * Nodes 1..127, channels 0..8, counts -524287..524287 (int20; -524288
 * marks "no value" for a channel a frame does not carry). All integers and
 * bit fields little-endian (Intel order, as a DBC's @1). */
#ifndef MAR_PROTO_CAN_H
#define MAR_PROTO_CAN_H

#include <stddef.h>
#include <stdint.h>

#include "mar_proto.h"

#define MAR_CAN_ESTOP 0x001u
#define MAR_CAN_ESTOP_RELEASE 0x002u
#define MAR_CAN_SYNC 0x080u
#define MAR_CAN_EMCY 0x080u             /* + node */
#define MAR_CAN_STATUS 0x180u           /* + node */
#define MAR_CAN_SETPOINT 0x200u         /* + node + 0x100 * pdo, pdo 0..2 */
#define MAR_CAN_POSITION 0x280u         /* + node + 0x100 * pdo, pdo 0..2 */
#define MAR_CAN_BANDS 0x580u            /* + node */
#define MAR_CAN_CONFIG 0x600u           /* + node */
#define MAR_CAN_LOUDNESS 0x680u         /* + node */
#define MAR_CAN_HEARTBEAT 0x700u        /* + node */

#define MAR_CAN_NODE_MAX 127            /* nodes 1..127: 7 bits beside the function code */
#define MAR_CAN_CHANNELS 9              /* channels 0..8: three PDOs of three */
#define MAR_CAN_PER_PDO 3
#define MAR_CAN_COUNTS_MAX 524287       /* int20 */
#define MAR_CAN_COUNTS_NONE (-524288)   /* "this frame carries no value for the channel" */
#define MAR_CAN_BANDS_MAX 7             /* band codes beside the counter and count in 8 bytes */

/* CONFIG parameters (byte 0 of a 0x600 + node frame). */
enum mar_can_param {
    MAR_CAN_PARAM_BEGIN = 0x01,         /* value: tick period [us]; channel 0xFF; starts a configuration */
    MAR_CAN_PARAM_WATCHDOG = 0x02,      /* value: watchdog [ticks], 1..65535; channel 0xFF */
    MAR_CAN_PARAM_MIN = 0x10,           /* value: int32 min [counts] */
    MAR_CAN_PARAM_MAX = 0x11,           /* value: int32 max [counts] */
    MAR_CAN_PARAM_SPEED = 0x12,         /* value: max speed [counts/s] */
    MAR_CAN_PARAM_ACCEL = 0x13,         /* value: max acceleration [counts/s^2] */
    MAR_CAN_PARAM_APPLY = 0x7F,         /* channel: how many channels came; value: seq; applies all */
};

typedef struct {
    uint16_t id;                        /* 11-bit identifier */
    uint8_t dlc;                        /* data bytes, 0..8 */
    uint8_t data[8];
} mar_can_frame;

/* Largest number of frames one message needs (CONFIG with 9 channels). */
#define MAR_CAN_FRAMES_MAX (3 + 4 * MAR_CAN_CHANNELS)

/* The frames of m; returns how many or MAR_E_*. Refuses what does not fit
 * the mapping (node 0 or above 127, channel above 8, counts outside int20,
 * a SYNC poll other than 0xFF, more than 7 LOUDNESS bands). Not carried on CAN, so decoded as 0: the
 * seq of ESTOP, ESTOP_RELEASE, HEARTBEAT and NACK; SYNC and STATUS carry
 * tick & 0xFF, and setpoint PDOs tick & 0xF (the receiver unwraps them). */
long mar_can_encode(const mar_msg *m, mar_can_frame *out, size_t cap);

/* The setpoint PDOs of one tick for any number of entries; counts are
 * saturated to +-524287 (the tick never fails on a value). Entries sorted
 * by (node, channel) give the fewest frames. Returns frames or MAR_E_*. */
long mar_can_encode_setpoints(uint32_t tick, const mar_setpoint_entry *entries, size_t n,
                              mar_can_frame *out, size_t cap);

/* Frames mar_can_encode_setpoints needs for n entries at most. */
size_t mar_can_setpoints_max(size_t n);

/* Counts saturated into the int20 range. */
int32_t mar_can_saturate(int32_t counts);

/* Receiver state: the unwrapped tick of the last SYNC, STATUS frames being
 * joined (per node), and one CONFIG being assembled. */
typedef struct {
    uint8_t parts;                      /* bit 0 header, bit 1 + k positions PDO k */
    uint8_t counter;                    /* tick & 0xF of the parts held */
    uint8_t tick8;                      /* the header's tick & 0xFF */
    uint8_t flags, state, n;
    uint16_t rejected, seq_gaps;
    int32_t position[MAR_CAN_CHANNELS]; /* [counts] */
    uint8_t n_bands;                    /* LOUDNESS bands held for the next LOUDNESS (0: none) */
    uint8_t bands_counter;              /* their frame counter & 0xF */
    uint8_t band[MAR_CAN_BANDS_MAX];    /* codes */
} mar_can_join;

typedef struct {
    int have_tick;
    uint32_t tick;                      /* last SYNC, unwrapped: previous + (counter - previous) mod 256 */
    mar_can_join join[MAR_CAN_NODE_MAX + 1];
    int config_open;
    mar_msg config;                     /* the configuration being assembled */
    uint8_t config_have[MAR_CONFIG_MAX];   /* per channel: bits of the 4 parameters received */
    int config_watchdog;
} mar_can_rx;

void mar_can_rx_init(mar_can_rx *rx);

/* Takes one received frame. Returns 1 when a whole message is in m, 0 when
 * the frame was a part (of STATUS or CONFIG), or MAR_E_*: unknown id, wrong
 * DLC, bad value, a setpoint PDO whose counter is not the last SYNC's
 * (MAR_E_STALE), APPLY without every parameter (MAR_E_INCOMPLETE).
 * Setpoint PDOs decode to SETPOINT messages of up to three entries, with
 * seq the unwrapped tick; STATUS is given once its header and all its
 * position PDOs (same counter) came, in any order; LOUDNESS at its 0x680
 * frame, with the bands of the node's bands frame before it when that
 * carried the same 4 counter bits (else without bands). */
int mar_can_rx_feed(mar_can_rx *rx, const mar_can_frame *f, mar_msg *m);

#endif
