#include "board.h"

#include <stdio.h>
#include <string.h>

#include <simavr/avr_adc.h>
#include <simavr/avr_uart.h>
#include <simavr/sim_cycle_timers.h>
#include <simavr/sim_elf.h>

enum { SUPPLY_MILLIVOLTS = 5000 };

/*
 * simavr's default sleep callback waits in real time. Our firmware sleeps
 * between ticks, so skipping the wait is what makes simulation much faster
 * than real time; simulated time still advances by the slept cycles.
 */
static void skip_sleep(avr_t *avr, avr_cycle_count_t how_long)
{
    (void)avr;
    (void)how_long;
}

static void uart0_output(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    board_t *board = (board_t *)param;
    if (board->on_uart_byte) {
        board->on_uart_byte(board->uart_context, (uint8_t)value);
    }
}

int board_load(board_t *board, const char *elf_path, const char *mcu, uint32_t frequency_hz)
{
    elf_firmware_t firmware;
    memset(&firmware, 0, sizeof firmware);
    memset(board, 0, sizeof *board);
    if (elf_read_firmware(elf_path, &firmware) != 0) {
        fprintf(stderr, "board: cannot read firmware '%s'\n", elf_path);
        return -1;
    }
    snprintf(firmware.mmcu, sizeof firmware.mmcu, "%s", mcu);
    firmware.frequency = frequency_hz;
    board->avr = avr_make_mcu_by_name(mcu);
    if (!board->avr) {
        fprintf(stderr, "board: simavr does not know MCU '%s'\n", mcu);
        return -1;
    }
    avr_init(board->avr);
    board->avr->frequency = frequency_hz;
    board->avr->vcc = SUPPLY_MILLIVOLTS;
    board->avr->avcc = SUPPLY_MILLIVOLTS;
    board->avr->aref = SUPPLY_MILLIVOLTS;
    avr_load_firmware(board->avr, &firmware);
    board->avr->sleep = skip_sleep;
    return 0;
}

void board_capture_uart0(board_t *board, board_uart_byte_fn on_byte, void *context)
{
    uint32_t flags = 0;
    avr_ioctl(board->avr, AVR_IOCTL_UART_GET_FLAGS('0'), &flags);
    /* No console echo, and no real-time pause when firmware polls the UART. */
    flags &= ~(uint32_t)(AVR_UART_FLAG_STDIO | AVR_UART_FLAG_POLL_SLEEP);
    avr_ioctl(board->avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
    board->on_uart_byte = on_byte;
    board->uart_context = context;
    avr_irq_register_notify(avr_io_getirq(board->avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT),
                            uart0_output, board);
}

void board_set_adc_millivolts(board_t *board, uint8_t channel, uint32_t millivolts)
{
    avr_raise_irq(avr_io_getirq(board->avr, AVR_IOCTL_ADC_GETIRQ, ADC_IRQ_ADC0 + channel), millivolts);
}

static avr_cycle_count_t send_next_byte(avr_t *avr, avr_cycle_count_t when, void *param)
{
    board_t *board = (board_t *)param;
    if (board->uart_input_sent >= board->uart_input_length) {
        return 0;
    }
    avr_raise_irq(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT),
                  board->uart_input[board->uart_input_sent++]);
    return when + avr->frequency / 1000;
}

void board_feed_uart0(board_t *board, const uint8_t *bytes, size_t length, uint32_t start_ms)
{
    board->uart_input = bytes;
    board->uart_input_length = length;
    board->uart_input_sent = 0;
    avr_cycle_timer_register(board->avr, (avr_cycle_count_t)board->avr->frequency / 1000 * start_ms,
                             send_next_byte, board);
}

int board_run(board_t *board, uint64_t max_cycles)
{
    int state = cpu_Running;
    while (board->avr->cycle < max_cycles) {
        state = avr_run(board->avr);
        if (state == cpu_Done || state == cpu_Crashed) {
            break;
        }
    }
    return state;
}
