#include "byte_queue.h"

#include <stdlib.h>
#include <string.h>

enum { INITIAL_CAPACITY = 4096 };

void byte_queue_free(byte_queue_t *queue)
{
    free(queue->bytes);
    memset(queue, 0, sizeof *queue);
}

static int make_room(byte_queue_t *queue, size_t count)
{
    if (queue->start + queue->length + count <= queue->capacity) {
        return 0;
    }
    /* Move the live bytes to the front before growing, so reads free space. */
    if (queue->start > 0) {
        memmove(queue->bytes, queue->bytes + queue->start, queue->length);
        queue->start = 0;
    }
    if (queue->length + count <= queue->capacity) {
        return 0;
    }
    size_t capacity = queue->capacity ? queue->capacity : INITIAL_CAPACITY;
    while (capacity < queue->length + count) {
        capacity *= 2;
    }
    uint8_t *bytes = realloc(queue->bytes, capacity);
    if (!bytes) {
        return -1;
    }
    queue->bytes = bytes;
    queue->capacity = capacity;
    return 0;
}

int byte_queue_push(byte_queue_t *queue, const uint8_t *bytes, size_t count)
{
    if (count == 0) {
        return 0;
    }
    if (make_room(queue, count) != 0) {
        return -1;
    }
    memcpy(queue->bytes + queue->start + queue->length, bytes, count);
    queue->length += count;
    return 0;
}

size_t byte_queue_pop(byte_queue_t *queue, uint8_t *out, size_t capacity)
{
    size_t count = queue->length < capacity ? queue->length : capacity;
    if (count > 0) {
        memcpy(out, queue->bytes + queue->start, count);
    }
    byte_queue_discard(queue, count);
    return count;
}

void byte_queue_discard(byte_queue_t *queue, size_t count)
{
    if (count > queue->length) {
        count = queue->length;
    }
    queue->start += count;
    queue->length -= count;
    if (queue->length == 0) {
        queue->start = 0;
    }
}
