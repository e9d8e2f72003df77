/*
 * One simulated board: an AVR from simavr with the project's firmware loaded,
 * set up the way the firmware expects on real hardware.
 */
#ifndef THERMOTILT_SIM_BOARD_H
#define THERMOTILT_SIM_BOARD_H

#include <stddef.h>
#include <stdint.h>

#include <simavr/sim_avr.h>
#include <simavr/sim_elf.h>
#include <simavr/sim_io.h>

typedef void (*board_uart_byte_fn)(void *context, uint8_t byte);
typedef void (*board_reset_fn)(void *context);

enum { BOARD_RESET_HOOKS = 4 };
/* simavr's run_cycle_limit: the most cycles one call of its run function executes (board_load). */
enum { BOARD_RUN_CYCLE_LIMIT = 1 << 16 };

/*
 * One profiler sample: the PC of the instruction that was executing, then
 * the call sites of the functions above it, innermost first (an interrupt's
 * entry counts as a call from the instruction it interrupted), as flash
 * byte addresses; BOARD_PROFILE_NO_FRAME pads a shallower stack.
 */
enum { BOARD_PROFILE_FRAMES = 8, BOARD_PROFILE_CALL_DEPTH = 64 };
#define BOARD_PROFILE_NO_FRAME UINT32_MAX
typedef struct board_profile_sample {
    uint32_t frames[BOARD_PROFILE_FRAMES];
} board_profile_sample_t;

typedef struct board_profile {
    board_profile_sample_t *samples; /* NULL while the profiler has never run */
    size_t capacity;
    size_t kept;
    uint64_t taken; /* kept, and those that found the buffer full */
    uint64_t period_cycles;
    uint64_t awake_cycles; /* since board_profile_start */
    uint64_t next_sample_at;
    /* A shadow of the call stack: each call site with the SP just below its return address. */
    struct {
        uint32_t call_site;
        uint16_t sp;
    } calls[BOARD_PROFILE_CALL_DEPTH];
    int depth;
    avr_run_t plain_run; /* simavr's run function while the profiler runs, else NULL */
} board_profile_t;

typedef struct board {
    avr_t *avr;
    board_uart_byte_fn on_uart_byte;
    void *uart_context;
    const uint8_t *uart_input;
    size_t uart_input_length;
    size_t uart_input_sent;
    avr_flashaddr_t exit_address; /* libgcc's _exit: cli, then an endless loop; 0 if none */
    uint16_t stack_floor;         /* first SRAM byte above .data/.bss/.noinit (_end) */
    avr_symbol_t **symbols;       /* the image's symbol table (simavr's, kept for the process) */
    uint32_t symbol_count;        /* entries in symbols */
    uint64_t run_until_cycle;     /* the end of the board_run in progress; 0 between runs */
    avr_io_t reset_watch;         /* an IO module of ours, so simavr tells us of each reset */
    board_reset_fn reset_hooks[BOARD_RESET_HOOKS];
    void *reset_contexts[BOARD_RESET_HOOKS];
    int reset_hook_count;
    uint64_t slept_cycles;        /* cycles simavr skipped while the CPU slept, since load */
    int one_instruction_per_call; /* board_run_one_instruction_per_call */
    board_profile_t profile;
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

/* A data-space symbol's SRAM address, or 0 when the image has no such symbol. */
uint16_t board_data_symbol(const board_t *board, const char *name);

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

/*
 * A sampling profiler of the awake CPU: every period_cycles executed cycles
 * it records the running instruction and its callers (board_profile_sample_t),
 * keeping up to capacity samples and counting the rest. Starting again
 * discards the samples. While it runs, each instruction passes through it
 * (simavr's run function is swapped for one that samples); stopped, the
 * board runs as if it never had been, and its samples stay readable until
 * the next start or board_free. Returns 0, or -1 for a zero period or
 * capacity, or out of memory.
 */
int board_profile_start(board_t *board, uint64_t period_cycles, size_t capacity);
void board_profile_stop(board_t *board);

/*
 * simavr executes instructions in runs until its next cycle timer is due or
 * an interrupt is pending (board_load sets its run_cycle_limit), which
 * simulates the same cycles as one instruction per call of its run
 * function, only faster. On (nonzero), this board runs one instruction per
 * call, as simavr does by default, so that a test can show the two agree.
 */
void board_run_one_instruction_per_call(board_t *board, int on);

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
