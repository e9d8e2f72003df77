#include "board.h"

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <simavr/avr_adc.h>
#include <simavr/avr_eeprom.h>
#include <simavr/avr_timer.h>
#include <simavr/avr_uart.h>
#include <simavr/sim_core.h>
#include <simavr/sim_cycle_timers.h>
#include <simavr/sim_elf.h>
#include <simavr/sim_io.h>

enum { SUPPLY_MILLIVOLTS = 5000, WGM_PHASE_CORRECT_8BIT = 1 };

/*
 * simavr's default sleep callback waits in real time. Our firmware sleeps
 * between ticks, so skipping the wait is what makes simulation much faster
 * than real time; simulated time still advances by the slept cycles, which
 * simavr adds right after this call: how_long and one more.
 */
static void skip_sleep(avr_t *avr, avr_cycle_count_t how_long)
{
    board_t *board = (board_t *)avr->custom.data;
    board->slept_cycles += how_long + 1;
}

/*
 * simavr 1.6 has no entry for waveform mode 1 (PWM, phase correct, TOP 0xFF),
 * which Arduino's init() selects for every timer except Timer0. An unknown
 * mode leaves TOP at 0, so each such timer "overflows" on every prescaler tick
 * (64 cycles): over a million events per simulated second on a Mega, which
 * made thermal_chamber simulate at 9x real time instead of 120x. simavr's
 * 8-bit "fc_pwm" kind counts to 0xFF instead. The firmware enables none of
 * these timers' interrupts and sim/l298n.c reads the PWM duty from the
 * registers, so simavr's single-slope count is good enough here.
 */
static void count_phase_correct_pwm_to_top(avr_t *avr)
{
    for (avr_io_t *io = avr->io_port; io; io = io->next) {
        if (strcmp(io->kind, "timer") != 0) {
            continue;
        }
        /* avr_io_t is the first member of simavr's timer module. */
        avr_timer_t *timer = (avr_timer_t *)io;
        if (timer->wgm_op[WGM_PHASE_CORRECT_8BIT].kind == avr_timer_wgm_none) {
            avr_timer_wgm_t phase_correct = AVR_TIMER_WGM_FCPWM8();
            timer->wgm_op[WGM_PHASE_CORRECT_8BIT] = phase_correct;
        }
    }
}

static void uart0_output(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    board_t *board = (board_t *)param;
    if (board->on_uart_byte) {
        board->on_uart_byte(board->uart_context, (uint8_t)value);
    }
}

__attribute__((format(printf, 3, 4))) static void report(char *error, size_t error_capacity, const char *format, ...)
{
    if (error_capacity == 0) {
        return;
    }
    va_list arguments;
    va_start(arguments, format);
    vsnprintf(error, error_capacity, format, arguments);
    va_end(arguments);
}

static avr_flashaddr_t symbol_address(avr_symbol_t *const *symbols, uint32_t count, const char *name)
{
    for (uint32_t i = 0; i < count; ++i) {
        if (strcmp(symbols[i]->symbol, name) == 0) {
            return symbols[i]->addr;
        }
    }
    return 0;
}

uint16_t board_data_symbol(const board_t *board, const char *name)
{
    /* Data-space symbols carry avr-gcc's 0x800000 offset. */
    return (uint16_t)(symbol_address(board->symbols, board->symbol_count, name) & 0xFFFF);
}

/* avr_load_firmware copies the flash image into the MCU's own memory. */
static void free_flash_image(elf_firmware_t *firmware)
{
    free(firmware->flash);
    firmware->flash = NULL;
}

static avr_cycle_count_t stop_here(avr_t *avr, avr_cycle_count_t when, void *param);
static avr_cycle_count_t send_next_byte(avr_t *avr, avr_cycle_count_t when, void *param);

/*
 * simavr runs one instruction per call of its run function unless
 * run_cycle_limit allows more: then avr_run_one goes on executing until the
 * next cycle timer is due, an interrupt is pending or the CPU stops running,
 * the same points at which it would have stopped one instruction at a time,
 * so the run is the same cycle for cycle. avr_reset sets the limit back to 1.
 */
static void set_run_cycle_limit(board_t *board)
{
    board->avr->run_cycle_limit = board->profile.plain_run || board->one_instruction_per_call ? 1
                                                                                              : BOARD_RUN_CYCLE_LIMIT;
}

static void after_reset(avr_io_t *io)
{
    board_t *board = (board_t *)((char *)io - offsetof(board_t, reset_watch));
    avr_t *avr = board->avr;
    set_run_cycle_limit(board);
    if (board->run_until_cycle > avr->cycle) {
        avr_cycle_timer_register(avr, board->run_until_cycle - avr->cycle, stop_here, board);
    }
    if (board->uart_input_sent < board->uart_input_length) {
        avr_cycle_timer_register(avr, avr->frequency / 1000, send_next_byte, board);
    }
    for (int i = 0; i < board->reset_hook_count; ++i) {
        board->reset_hooks[i](board->reset_contexts[i]);
    }
    board->profile.depth = 0;
}

int board_on_reset(board_t *board, board_reset_fn hook, void *context)
{
    if (board->reset_hook_count >= BOARD_RESET_HOOKS) {
        return -1;
    }
    board->reset_hooks[board->reset_hook_count] = hook;
    board->reset_contexts[board->reset_hook_count] = context;
    board->reset_hook_count++;
    return 0;
}

size_t board_eeprom_size(const board_t *board)
{
    return (size_t)board->avr->e2end + 1;
}

/* simavr's EEPROM ioctls return -1 whether or not they did anything, so the bounds are checked here. */
static int eeprom_access(board_t *board, uint32_t request, size_t offset, uint8_t *bytes, size_t length)
{
    size_t size = board_eeprom_size(board);
    if (offset > size || length > size - offset) {
        return -1;
    }
    if (length == 0) {
        return 0;
    }
    avr_eeprom_desc_t desc = {.ee = bytes, .offset = (uint16_t)offset, .size = (uint32_t)length};
    avr_ioctl(board->avr, request, &desc);
    return 0;
}

int board_eeprom_read(board_t *board, size_t offset, uint8_t *out, size_t length)
{
    return eeprom_access(board, AVR_IOCTL_EEPROM_GET, offset, out, length);
}

int board_eeprom_write(board_t *board, size_t offset, const uint8_t *bytes, size_t length)
{
    /* AVR_IOCTL_EEPROM_SET only reads from ee. */
    return eeprom_access(board, AVR_IOCTL_EEPROM_SET, offset, (uint8_t *)bytes, length);
}

int board_load(board_t *board, const char *elf_path, const char *mcu, uint32_t frequency_hz, char *error,
               size_t error_capacity)
{
    elf_firmware_t firmware;
    memset(&firmware, 0, sizeof firmware);
    memset(board, 0, sizeof *board);
    if (frequency_hz == 0) {
        report(error, error_capacity, "board: the clock frequency must be positive");
        return -1;
    }
    if (elf_read_firmware(elf_path, &firmware) != 0) {
        report(error, error_capacity, "board: cannot read firmware '%s'", elf_path);
        return -1;
    }
    snprintf(firmware.mmcu, sizeof firmware.mmcu, "%s", mcu);
    firmware.frequency = frequency_hz;
    board->avr = avr_make_mcu_by_name(mcu);
    if (!board->avr) {
        free_flash_image(&firmware);
        report(error, error_capacity, "board: simavr does not know MCU '%s'", mcu);
        return -1;
    }
    avr_init(board->avr);
    board->avr->frequency = frequency_hz;
    board->avr->vcc = SUPPLY_MILLIVOLTS;
    board->avr->avcc = SUPPLY_MILLIVOLTS;
    board->avr->aref = SUPPLY_MILLIVOLTS;
    avr_load_firmware(board->avr, &firmware);
    /* simavr never frees an image's symbols: the board keeps them. */
    board->symbols = firmware.symbol;
    board->symbol_count = firmware.symbolcount;
    board->exit_address = symbol_address(board->symbols, board->symbol_count, "_exit");
    board->stack_floor = board_data_symbol(board, "_end");
    if (board->stack_floor != 0) {
        memset(board->avr->data + board->stack_floor, BOARD_STACK_PAINT,
               (size_t)board->avr->ramend + 1 - board->stack_floor);
    }
    free_flash_image(&firmware);
    /* simavr hands its callbacks only the avr; custom.data goes nowhere else, as we set no custom init. */
    board->avr->custom.data = board;
    board->avr->sleep = skip_sleep;
    count_phase_correct_pwm_to_top(board->avr);
    board->reset_watch.kind = "thermotilt_board";
    board->reset_watch.reset = after_reset;
    avr_register_io(board->avr, &board->reset_watch);
    set_run_cycle_limit(board);
    return 0;
}

int board_hang(board_t *board)
{
    if (board->exit_address == 0) {
        return -1;
    }
    avr_t *avr = board->avr;
    avr->sreg[S_I] = 0;
    avr->pc = board->exit_address;
    if (avr->state == cpu_Sleeping) {
        avr->state = cpu_Running;
    }
    return 0;
}

size_t board_stack_untouched(const board_t *board, size_t *capacity)
{
    *capacity = 0;
    if (board->stack_floor == 0) {
        return 0;
    }
    const avr_t *avr = board->avr;
    *capacity = (size_t)avr->ramend + 1 - board->stack_floor;
    size_t untouched = 0;
    /* The stack grows down from RAMEND: count painted bytes from the floor up. */
    while (untouched < *capacity && avr->data[board->stack_floor + untouched] == BOARD_STACK_PAINT) {
        ++untouched;
    }
    return untouched;
}

void board_cycle_counts(const board_t *board, uint64_t *awake, uint64_t *asleep)
{
    *asleep = board->slept_cycles;
    *awake = board->avr->cycle - board->slept_cycles;
}

enum {
    OPCODE_CALL_MASK = 0xFE0E,
    OPCODE_CALL = 0x940E,
    OPCODE_RCALL_MASK = 0xF000,
    OPCODE_RCALL = 0xD000,
    OPCODE_ICALL = 0x9509,
    OPCODE_EICALL = 0x9519,
};

/* "rcall ." only reserves stack space: avr-gcc's way to grow a frame by a return address. */
static int is_call(uint16_t opcode)
{
    return (opcode & OPCODE_CALL_MASK) == OPCODE_CALL ||
           ((opcode & OPCODE_RCALL_MASK) == OPCODE_RCALL && opcode != OPCODE_RCALL) || opcode == OPCODE_ICALL ||
           opcode == OPCODE_EICALL;
}

/* Calls deeper than the shadow holds go unrecorded; the SP rule never pops a shallower one for them. */
static void push_call(board_profile_t *profile, uint32_t call_site, uint16_t sp)
{
    if (profile->depth < BOARD_PROFILE_CALL_DEPTH) {
        profile->calls[profile->depth].call_site = call_site;
        profile->calls[profile->depth].sp = sp;
        profile->depth++;
    }
}

static void take_sample(board_profile_t *profile, uint32_t pc)
{
    profile->taken++;
    if (profile->kept == profile->capacity) {
        return;
    }
    board_profile_sample_t *sample = &profile->samples[profile->kept++];
    sample->frames[0] = pc;
    for (int frame = 1; frame < BOARD_PROFILE_FRAMES; ++frame) {
        sample->frames[frame] = frame <= profile->depth ? profile->calls[profile->depth - frame].call_site
                                                        : BOARD_PROFILE_NO_FRAME;
    }
}

/* The return address an interrupt's entry pushed, big-endian in words above SP. */
static uint32_t interrupted_at(const avr_t *avr, uint16_t sp)
{
    uint32_t word_address = 0;
    for (int i = 1; i <= avr->address_size; ++i) {
        word_address = word_address << 8 | avr->data[sp + i];
    }
    return word_address * 2;
}

/*
 * simavr's run function with the profiler around it: one instruction (or a
 * slice of sleep), then interrupts. The stack's shadow follows calls by
 * their opcode and returns by the SP rising above a call's return address,
 * so code that unwinds the stack by other means is followed too.
 */
static void run_profiled(avr_t *avr)
{
    board_t *board = (board_t *)avr->custom.data;
    board_profile_t *profile = &board->profile;
    int executes = avr->state == cpu_Running;
    avr_flashaddr_t pc = avr->pc;
    uint16_t sp_before = _avr_sp_get(avr);
    uint8_t interrupts_running = avr->interrupts.running_ptr;
    avr_cycle_count_t cycle_before = avr->cycle;
    uint64_t slept_before = board->slept_cycles;

    profile->plain_run(avr);

    uint16_t sp = _avr_sp_get(avr);
    int interrupt_entered = avr->interrupts.running_ptr > interrupts_running;
    uint16_t sp_after_instruction = interrupt_entered ? (uint16_t)(sp + avr->address_size) : sp;
    if (executes) {
        profile->awake_cycles += (avr->cycle - cycle_before) - (board->slept_cycles - slept_before);
        while (profile->awake_cycles >= profile->next_sample_at) {
            take_sample(profile, pc);
            profile->next_sample_at += profile->period_cycles;
        }
        if (is_call((uint16_t)(avr->flash[pc] | avr->flash[pc + 1] << 8))) {
            push_call(profile, pc, (uint16_t)(sp_before - avr->address_size));
        }
    }
    while (profile->depth > 0 && profile->calls[profile->depth - 1].sp < sp_after_instruction) {
        profile->depth--;
    }
    if (interrupt_entered) {
        push_call(profile, interrupted_at(avr, sp), sp);
    }
}

int board_profile_start(board_t *board, uint64_t period_cycles, size_t capacity)
{
    board_profile_t *profile = &board->profile;
    if (period_cycles == 0 || capacity == 0) {
        return -1;
    }
    board_profile_sample_t *samples = realloc(profile->samples, capacity * sizeof *samples);
    if (!samples) {
        return -1;
    }
    avr_run_t plain_run = profile->plain_run ? profile->plain_run : board->avr->run;
    memset(profile, 0, sizeof *profile);
    profile->samples = samples;
    profile->capacity = capacity;
    profile->period_cycles = period_cycles;
    profile->next_sample_at = period_cycles;
    profile->plain_run = plain_run;
    board->avr->run = run_profiled;
    set_run_cycle_limit(board);
    return 0;
}

void board_profile_stop(board_t *board)
{
    if (board->profile.plain_run) {
        board->avr->run = board->profile.plain_run;
        board->profile.plain_run = NULL;
        set_run_cycle_limit(board);
    }
}

void board_run_one_instruction_per_call(board_t *board, int on)
{
    board->one_instruction_per_call = on != 0;
    set_run_cycle_limit(board);
}

void board_free(board_t *board)
{
    free(board->profile.samples);
    if (board->avr) {
        avr_terminate(board->avr);
        /* avr_make_mcu_by_name allocated the MCU with avr_t at its start. */
        free(board->avr);
    }
    memset(board, 0, sizeof *board);
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
    avr_irq_register_notify(avr_io_getirq(board->avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT), uart0_output,
                            board);
}

/*
 * The datasheet's ideal ADC reads Vin * 1024 / Vref with its first
 * transition (0 to 1) at half an LSB ("ADC Accuracy Definitions"): it
 * rounds, so a reading is not biased by half a code (0.045 degC on a
 * thermistor at 25 degC). simavr 1.6 converts whole millivolts as
 * Vin * 1023 / Vref instead; it gets the smallest whole millivolt value that
 * it converts to the ideal code, so the firmware reads what a real ATmega
 * would, for any fraction of a millivolt.
 */
void board_set_adc_millivolts(board_t *board, uint8_t channel, double millivolts)
{
    enum { ADC_STEPS = 1024, ADC_MAX_CODE = 1023 };
    uint32_t code = 0;
    if (millivolts > 0) {
        double ideal = millivolts * ADC_STEPS / SUPPLY_MILLIVOLTS + 0.5;
        code = ideal >= ADC_MAX_CODE ? ADC_MAX_CODE : (uint32_t)ideal;
    }
    uint32_t simavr_millivolts = (code * SUPPLY_MILLIVOLTS + ADC_MAX_CODE - 1) / ADC_MAX_CODE;
    avr_raise_irq(avr_io_getirq(board->avr, AVR_IOCTL_ADC_GETIRQ, ADC_IRQ_ADC0 + channel), simavr_millivolts);
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
    avr_cycle_timer_register(board->avr, (avr_cycle_count_t)board->avr->frequency / 1000 * start_ms, send_next_byte,
                             board);
}

static avr_cycle_count_t stop_here(avr_t *avr, avr_cycle_count_t when, void *param)
{
    (void)avr;
    (void)when;
    (void)param;
    return 0;
}

int board_run(board_t *board, uint64_t until_cycle)
{
    avr_t *avr = board->avr;
    int state = avr->state;
    if (avr->cycle >= until_cycle) {
        return state;
    }
    /* A sleeping CPU skips ahead to the next cycle timer; this one is it. */
    board->run_until_cycle = until_cycle;
    avr_cycle_timer_register(avr, until_cycle - avr->cycle, stop_here, board);
    while (avr->cycle < until_cycle) {
        state = avr_run(avr);
        if (state == cpu_Done || state == cpu_Crashed) {
            break;
        }
    }
    avr_cycle_timer_cancel(avr, stop_here, board);
    board->run_until_cycle = 0;
    return state;
}
