#include "line_noise.h"

/* splitmix64 (Steele, Lea and Flood). */
uint64_t splitmix64_next(uint64_t *state)
{
    uint64_t z = (*state += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

void line_noise_set(line_noise_t *noise, double probability, uint64_t state)
{
    /* At probability 1, every draw is below the threshold. */
    const uint64_t draws = 1ull << 53;
    if (probability <= 0) {
        noise->threshold = 0;
    } else if (probability >= 1) {
        noise->threshold = draws;
    } else {
        noise->threshold = (uint64_t)(probability * (double)draws);
    }
    noise->state = state;
}

uint8_t line_noise_apply(line_noise_t *noise, uint8_t byte)
{
    if (noise->threshold == 0) {
        return byte;
    }
    if ((splitmix64_next(&noise->state) >> 11) >= noise->threshold) {
        return byte;
    }
    noise->corrupted_bytes++;
    return (uint8_t)(byte ^ (1u << (splitmix64_next(&noise->state) >> 61)));
}
