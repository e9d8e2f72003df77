#define _GNU_SOURCE /* ptsname_r, cfmakeraw */
#include "uart_bridge.h"

#include <errno.h>
#include <fcntl.h>
#include <stdlib.h>
#include <string.h>
#include <termios.h>
#include <unistd.h>

#include <simavr/avr_uart.h>
#include <simavr/sim_cycle_timers.h>

enum { LINE_BAUD = 115200, BITS_PER_BYTE = 10, PTY_READ_CHUNK = 4096 };

static void on_firmware_byte(void *context, uint8_t byte)
{
    uart_bridge_t *bridge = (uart_bridge_t *)context;
    byte = line_noise_apply(&bridge->noise[0], byte);
    byte_queue_push(&bridge->from_firmware, &byte, 1);
    if (bridge->pty_master < 0) {
        return;
    }
    if (bridge->pty_backlog.length >= UART_BRIDGE_PTY_BACKLOG || byte_queue_push(&bridge->pty_backlog, &byte, 1) != 0) {
        bridge->pty_dropped_bytes++;
    }
}

static avr_cycle_count_t line_free_cycle(const uart_bridge_t *bridge)
{
    return (bridge->line_free_scaled + LINE_BAUD - 1) / LINE_BAUD;
}

static avr_cycle_count_t deliver_next_byte(avr_t *avr, avr_cycle_count_t when, void *param)
{
    (void)avr;
    uart_bridge_t *bridge = (uart_bridge_t *)param;
    uint8_t byte = 0;
    if (bridge->receiver_full || byte_queue_pop(&bridge->to_firmware, &byte, 1) == 0) {
        return 0;
    }
    uint64_t now_scaled = (uint64_t)when * LINE_BAUD;
    if (bridge->line_free_scaled < now_scaled) {
        bridge->line_free_scaled = now_scaled;
    }
    bridge->line_free_scaled += bridge->byte_time_scaled;
    /* This can answer XOFF right away, when simavr's receive FIFO fills. */
    avr_raise_irq(bridge->firmware_input, line_noise_apply(&bridge->noise[1], byte));
    if (bridge->receiver_full || bridge->to_firmware.length == 0) {
        return 0;
    }
    return line_free_cycle(bridge);
}

static void schedule_delivery(uart_bridge_t *bridge)
{
    if (bridge->receiver_full || bridge->to_firmware.length == 0 ||
        avr_cycle_timer_status(bridge->avr, deliver_next_byte, bridge) != 0) {
        return;
    }
    avr_cycle_count_t now = bridge->avr->cycle;
    avr_cycle_count_t at = line_free_cycle(bridge);
    avr_cycle_timer_register(bridge->avr, at > now ? at - now : 0, deliver_next_byte, bridge);
}

static void on_xon(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    (void)value;
    uart_bridge_t *bridge = (uart_bridge_t *)param;
    bridge->receiver_full = 0;
    schedule_delivery(bridge);
}

static void on_xoff(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    uart_bridge_t *bridge = (uart_bridge_t *)param;
    bridge->receiver_full = value != 0;
    schedule_delivery(bridge);
}

void uart_bridge_attach(uart_bridge_t *bridge, board_t *board)
{
    memset(bridge, 0, sizeof *bridge);
    bridge->avr = board->avr;
    bridge->pty_master = -1;
    bridge->byte_time_scaled = (uint64_t)BITS_PER_BYTE * board->avr->frequency;
    /* The receiver is off until the firmware enables it; simavr says XON then. */
    bridge->receiver_full = 1;
    bridge->firmware_input = avr_io_getirq(board->avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT);
    board_capture_uart0(board, on_firmware_byte, bridge);
    avr_irq_register_notify(avr_io_getirq(board->avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XON), on_xon, bridge);
    avr_irq_register_notify(avr_io_getirq(board->avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XOFF), on_xoff, bridge);
}

void uart_bridge_free(uart_bridge_t *bridge)
{
    if (bridge->pty_master >= 0) {
        close(bridge->pty_master);
    }
    byte_queue_free(&bridge->from_firmware);
    byte_queue_free(&bridge->to_firmware);
    byte_queue_free(&bridge->pty_backlog);
    bridge->pty_master = -1;
}

size_t uart_bridge_pending(const uart_bridge_t *bridge)
{
    return bridge->from_firmware.length;
}

size_t uart_bridge_read(uart_bridge_t *bridge, uint8_t *out, size_t capacity)
{
    return byte_queue_pop(&bridge->from_firmware, out, capacity);
}

int uart_bridge_write(uart_bridge_t *bridge, const uint8_t *bytes, size_t length)
{
    if (byte_queue_push(&bridge->to_firmware, bytes, length) != 0) {
        return -1;
    }
    schedule_delivery(bridge);
    return 0;
}

void uart_bridge_set_corruption(uart_bridge_t *bridge, double probability, uint64_t seed)
{
    uint64_t from_firmware = splitmix64_next(&seed);
    uint64_t to_firmware = splitmix64_next(&seed);
    line_noise_set(&bridge->noise[0], probability, from_firmware);
    line_noise_set(&bridge->noise[1], probability, to_firmware);
}

/* Raw before anyone opens the slave: an echo would loop our frames back. */
static int configure_pty(int master, char *path, size_t path_capacity)
{
    if (grantpt(master) != 0 || unlockpt(master) != 0 || ptsname_r(master, path, path_capacity) != 0) {
        return -1;
    }
    struct termios raw;
    if (tcgetattr(master, &raw) != 0) {
        return -1;
    }
    cfmakeraw(&raw);
    if (tcsetattr(master, TCSANOW, &raw) != 0) {
        return -1;
    }
    int flags = fcntl(master, F_GETFL);
    if (flags < 0 || fcntl(master, F_SETFL, flags | O_NONBLOCK) != 0) {
        return -1;
    }
    return fcntl(master, F_SETFD, FD_CLOEXEC);
}

const char *uart_bridge_open_pty(uart_bridge_t *bridge)
{
    if (bridge->pty_master >= 0) {
        return bridge->pty_path;
    }
    int master = posix_openpt(O_RDWR | O_NOCTTY);
    if (master < 0) {
        return NULL;
    }
    if (configure_pty(master, bridge->pty_path, sizeof bridge->pty_path) != 0) {
        int saved = errno;
        close(master);
        errno = saved;
        return NULL;
    }
    bridge->pty_master = master;
    return bridge->pty_path;
}

void uart_bridge_poll_pty(uart_bridge_t *bridge)
{
    if (bridge->pty_master < 0) {
        return;
    }
    uint8_t chunk[PTY_READ_CHUNK];
    ssize_t count;
    /* EAGAIN: nothing to read; EIO: no client has the slave open. */
    while ((count = read(bridge->pty_master, chunk, sizeof chunk)) > 0) {
        uart_bridge_write(bridge, chunk, (size_t)count);
    }
    byte_queue_t *backlog = &bridge->pty_backlog;
    while (backlog->length > 0 &&
           (count = write(bridge->pty_master, backlog->bytes + backlog->start, backlog->length)) > 0) {
        byte_queue_discard(backlog, (size_t)count);
    }
}
