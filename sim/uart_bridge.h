/*
 * USART0 of a simulated board as a byte stream for the host side: every byte
 * the firmware sends is kept until read, bytes for the firmware arrive at the
 * 115200-baud line rate and wait while simavr's receiver says XOFF. An
 * optional pseudo-terminal lets a serial program talk to the board, and a
 * fault hook corrupts bytes on the wire.
 */
#ifndef THERMOTILT_SIM_UART_BRIDGE_H
#define THERMOTILT_SIM_UART_BRIDGE_H

#include <stddef.h>
#include <stdint.h>

#include "board.h"
#include "byte_queue.h"
#include "line_noise.h"

enum { UART_BRIDGE_PTY_PATH_CAPACITY = 128 };

typedef struct uart_bridge {
    avr_t *avr;
    avr_irq_t *firmware_input;
    byte_queue_t from_firmware;
    byte_queue_t to_firmware;
    int receiver_full; /* simavr said XOFF and not yet XON */
    /* When the line is free for the next byte, in cycles x baud (exact). */
    uint64_t line_free_scaled;
    uint64_t byte_time_scaled;
    line_noise_t noise[2]; /* [0] bytes from the firmware, [1] bytes to it */
    int pty_master;
    char pty_path[UART_BRIDGE_PTY_PATH_CAPACITY];
    byte_queue_t pty_backlog;
    uint64_t pty_dropped_bytes;
} uart_bridge_t;

/* Takes over USART0 of a board that has not run yet. */
void uart_bridge_attach(uart_bridge_t *bridge, board_t *board);
void uart_bridge_free(uart_bridge_t *bridge);

size_t uart_bridge_pending(const uart_bridge_t *bridge);
/* Moves up to capacity bytes the firmware sent into out; returns how many. */
size_t uart_bridge_read(uart_bridge_t *bridge, uint8_t *out, size_t capacity);
/* Queues bytes for the firmware; returns 0, or -1 when memory ran out. */
int uart_bridge_write(uart_bridge_t *bridge, const uint8_t *bytes, size_t length);

/*
 * Each byte, in each direction, gets one random bit flipped with this
 * probability (0 turns corruption off). The same seed gives the same flips.
 */
void uart_bridge_set_corruption(uart_bridge_t *bridge, double probability, uint64_t seed);

/*
 * Opens a pseudo-terminal (raw, so nothing is echoed back) and returns its
 * slave path, or NULL with errno set. Opening again returns the same path.
 */
const char *uart_bridge_open_pty(uart_bridge_t *bridge);

/*
 * Moves bytes between the pty and the board without blocking: what a client
 * wrote goes to the firmware, what the firmware sent goes to the client.
 * While nobody reads, up to UART_BRIDGE_PTY_BACKLOG bytes wait; later ones
 * are dropped and counted.
 */
void uart_bridge_poll_pty(uart_bridge_t *bridge);

enum { UART_BRIDGE_PTY_BACKLOG = 64 * 1024 };

#endif
