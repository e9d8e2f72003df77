/* A first-in first-out byte buffer that grows as needed. */
#ifndef THERMOTILT_SIM_BYTE_QUEUE_H
#define THERMOTILT_SIM_BYTE_QUEUE_H

#include <stddef.h>
#include <stdint.h>

typedef struct byte_queue {
    uint8_t *bytes;
    size_t start;
    size_t length;
    size_t capacity;
} byte_queue_t;

void byte_queue_free(byte_queue_t *queue);

/* Returns 0, or -1 when memory ran out (nothing was added then). */
int byte_queue_push(byte_queue_t *queue, const uint8_t *bytes, size_t count);

/* Moves up to capacity bytes out; returns how many. */
size_t byte_queue_pop(byte_queue_t *queue, uint8_t *out, size_t capacity);

/* Drops the first count bytes (at most all of them). */
void byte_queue_discard(byte_queue_t *queue, size_t count);

#endif
