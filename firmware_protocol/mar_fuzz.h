/* Fuzzing the codec: random messages, mutated on the wire, through the
 * deframer and the CAN receiver. Used by `marionette bench fuzz` and the C
 * test; no allocation, deterministic for a seed. */
#ifndef MAR_FUZZ_H
#define MAR_FUZZ_H

#include <stdint.h>

#include "mar_proto.h"

typedef struct {
    uint64_t frames;            /* serial frames made */
    uint64_t clean;             /* sent unchanged (some right after garbage) */
    uint64_t clean_lost;        /* of those, not decoded exactly: must be 0 */
    uint64_t mutated;           /* wire bytes changed: bit flips, bursts, insertions, deletions, truncation */
    uint64_t crc_trials;        /* mutated frames that are well formed but say something else:
                                   only the CRC stands in their way */
    uint64_t mutated_rejected;  /* mutated frames that gave no message */
    uint64_t mutated_same;      /* gave the original message (e.g. a non-canonical COBS block) */
    uint64_t accepted_corrupt;  /* gave a different message: the CRC missed (expected crc_trials * 2^-32) */
    uint64_t crc16_accepted;    /* of the crc_trials, those a 16-bit check would pass (expected crc_trials * 2^-16) */
    uint64_t low_weight;        /* bodies with 1..5 flipped bits */
    uint64_t low_weight_accepted;   /* must be 0: CRC-32C has Hamming distance 6 up to 5243 bits */
    uint64_t garbage_runs;      /* runs of random bytes */
    uint64_t garbage_bytes;
    uint64_t garbage_accepted;  /* messages decoded from random bytes */
    uint64_t wire_bytes;        /* bytes through the deframer */
    uint64_t can_frames;        /* random and mutated frames through the CAN receiver */
    uint64_t can_messages;      /* messages it gave */
} mar_fuzz_report;

/* xorshift64* step; state must not be 0. */
uint64_t mar_fuzz_next(uint64_t *state);

/* A random valid message of any type. can: only what the CAN mapping
 * carries (nodes 1..127, channels 0..8 in ascending order, int20 counts,
 * SYNC poll 0xFF, seq 0 where CAN does not carry it). */
void mar_fuzz_random_msg(uint64_t *state, mar_msg *m, int can);

/* Runs n_frames serial frames (and n_frames / 4 CAN frames) from seed. */
void mar_fuzz_run(uint64_t seed, uint64_t n_frames, mar_fuzz_report *r);

#endif
