/*
 * The twin's wire fault, on its own so that the integrity benchmark corrupts
 * bytes exactly as the UART bridge does: each byte gets one random bit
 * flipped with a given probability. splitmix64 rather than rand(), so the
 * same seed gives the same flips on every machine and libc.
 */
#ifndef THERMOTILT_SIM_LINE_NOISE_H
#define THERMOTILT_SIM_LINE_NOISE_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct line_noise {
    uint64_t threshold; /* a 53-bit draw below it corrupts the byte */
    uint64_t state;
    uint64_t corrupted_bytes;
} line_noise_t;

uint64_t splitmix64_next(uint64_t *state);

/* Probability 0 turns the noise off; the state starts at `state`. */
void line_noise_set(line_noise_t *noise, double probability, uint64_t state);
uint8_t line_noise_apply(line_noise_t *noise, uint8_t byte);

#ifdef __cplusplus
}
#endif

#endif
