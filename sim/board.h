/*
 * One simulated board: an AVR from simavr with the project's firmware loaded,
 * set up the way the firmware expects on real hardware.
 */
#ifndef THERMOTILT_SIM_BOARD_H
#define THERMOTILT_SIM_BOARD_H

#include <stddef.h>
#include <stdint.h>

#include <simavr/sim_avr.h>
#include <simavr/sim_io.h>

typedef void (*board_uart_byte_fn)(void *context, uint8_t byte);
typedef void (*board_reset_fn)(void *context);

enum { BOARD_RESET_HOOKS = 4 };

typedef struct board {
    avr_t *avr;
    board_uart_byte_fn on_uart_byte;
    void *uart_context;
    const uint8_t *uart_input;
    size_t uart_input_length;
    size_t uart_input_sent;
    avr_flashaddr_t exit_address; /* libgcc's _exit: cli, then an endless loop; 0 if none */
    uint16_t stack_floor;         /* first SRAM byte above .data/.bss/.noinit (_end) */
    uint64_t run_until_cycle;     /* the end of the board_run in progress; 0 between runs */
    avr_io_t reset_watch;         /* an IO module of ours, so simavr tells us of each reset */
    board_reset_fn reset_hooks[BOARD_RESET_HOOKS];
    void *reset_contexts[BOARD_RESET_HOOKS];
    int reset_hook_count;
    uint64_t slept_cycles; /* cycles simavr skipped while the CPU slept, since load */
} board_t;

/*
 * Loads an ELF onto a new MCU. Arduino-built ELFs carry no .mmcu section, so
 * the MCU name and clock are given here. Returns 0 on success, else writes
 * one line into error (when error_capacity > 0) and returns -1.
 */
int board_load(board_t *board, const char *elf_path, const char *mcu, uint32_t frequency_hz, char *error,
               size_t error_capacity);

/*
 * Hangs the firmware as a deadlock would: interrupts off and the CPU in
 * libgcc's _exit loop, so only the watchdog can bring it
 * back. Returns 0, or -1 when the image has no such loop.
 */
int board_hang(board_t *board);

/*
 * The SRAM between the static data and RAMEND, painted at load with
 * BOARD_STACK_PAINT: how many of its bytes the stack has never reached, and
 * how many it holds in all (both 0 when the image has no _end symbol).
 */
enum { BOARD_STACK_PAINT = 0xA5 };
size_t board_stack_untouched(const board_t *board, size_t *capacity);

/*
 * A reset of the MCU (the watchdog's) drops every simavr cycle timer, also
 * those of the parts outside it, which a real reset leaves running: each
 * part that keeps time registers a hook here to start its timers again. The
 * board's own (the end of board_run, board_feed_uart0) it restarts itself.
 * Returns 0, or -1 when BOARD_RESET_HOOKS are taken.
 */
int board_on_reset(board_t *board, board_reset_fn hook, void *context);

/*
 * The EEPROM, which keeps its bytes across resets as the chip's does. Both
 * return 0, or -1 when offset + length lies beyond it.
 */
size_t board_eeprom_size(const board_t *board);
int board_eeprom_read(board_t *board, size_t offset, uint8_t *out, size_t length);
int board_eeprom_write(board_t *board, size_t offset, const uint8_t *bytes, size_t length);

/*
 * Cycles since load the CPU executed instructions (awake) and slept; the
 * two add up to the cycles simulated. Always counted: it costs an addition
 * per sleep.
 */
void board_cycle_counts(const board_t *board, uint64_t *awake, uint64_t *asleep);

/* Releases the MCU; the board can be loaded again afterwards. */
void board_free(board_t *board);

/* Raw bytes the firmware writes on USART0 go to this callback instead of stdout. */
void board_capture_uart0(board_t *board, board_uart_byte_fn on_byte, void *context);

/*
 * Holds an analog input (ADC0..ADC7: simavr 1.6 models no more) at a
 * voltage, as a divider with a fixed resistance would. The firmware reads
 * the datasheet's code, Vin * 1024 / 5 V truncated to 0..1023.
 */
void board_set_adc_millivolts(board_t *board, uint8_t channel, double millivolts);

/*
 * Sends bytes to the firmware's USART0 from start_ms of simulated time on,
 * one per millisecond (well below 115200 baud, so the receive buffer never
 * overflows). The bytes must stay valid while the board runs.
 */
void board_feed_uart0(board_t *board, const uint8_t *bytes, size_t length, uint32_t start_ms);

/*
 * Runs until the firmware stops, crashes or the cycle count reaches
 * until_cycle (a sleeping CPU stops there too, not at its next wake-up);
 * returns the final state.
 */
int board_run(board_t *board, uint64_t until_cycle);

#endif
