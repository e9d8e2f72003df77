/*
 * A flat C interface over one simulated board, for ctypes
 * (host/thermotilt/twin/boards.py): the firmware image in simavr with its USART0
 * bridge, analog inputs with fault overrides, and optionally the LSM9DS0
 * model on TWI and the L298N observer on the Mega's pins. Everything but the
 * pty is deterministic: the same calls give the same bytes.
 */
#ifndef THERMOTILT_SIM_TWIN_H
#define THERMOTILT_SIM_TWIN_H

#include <stddef.h>
#include <stdint.h>

typedef struct twin twin_t;

enum twin_state { TWIN_RUNNING = 0, TWIN_DONE = 1, TWIN_CRASHED = 2 };
enum twin_adc_fault { TWIN_ADC_NONE = 0, TWIN_ADC_OPEN = 1, TWIN_ADC_SHORT = 2 };
/* simavr 1.6 models ADC0..ADC7 only, on every MCU. */
enum { TWIN_ADC_CHANNELS = 8, TWIN_SUPPLY_MILLIVOLTS = 5000 };

/* NULL on failure, with a readable reason in error. */
twin_t *twin_create(const char *elf_path, const char *mcu, uint32_t frequency_hz, char *error, size_t error_capacity);
void twin_free(twin_t *twin);

/* Runs until the cycle count reaches until_cycle; returns a twin_state. */
int twin_run_until(twin_t *twin, uint64_t until_cycle);
uint64_t twin_cycles(const twin_t *twin);

size_t twin_uart_pending(const twin_t *twin);
size_t twin_uart_read(twin_t *twin, uint8_t *out, size_t capacity);
int twin_uart_write(twin_t *twin, const uint8_t *bytes, size_t length);
/* The pty's slave path, or NULL (errno says why). */
const char *twin_uart_open_pty(twin_t *twin);
void twin_uart_set_corruption(twin_t *twin, double probability, uint64_t seed);
uint64_t twin_uart_corrupted_bytes(const twin_t *twin);
uint64_t twin_pty_dropped_bytes(const twin_t *twin);

/* A deadlocked firmware (board_hang): 0, or -1 when the image cannot be hung. */
int twin_hang(twin_t *twin);

/*
 * The MCU's EEPROM (1 KB on the ATmega328P, 4 KB on the ATmega2560), which
 * keeps its bytes across resets and whose firmware writes land at once.
 * Write before the first run to give the firmware a stored block at boot.
 * Read and write return 0, or -1 when offset + length lies beyond it.
 */
size_t twin_eeprom_size(const twin_t *twin);
int twin_eeprom_read(twin_t *twin, size_t offset, uint8_t *out, size_t length);
int twin_eeprom_write(twin_t *twin, size_t offset, const uint8_t *bytes, size_t length);

/* Cycles since create the CPU executed (awake) and slept; they add up to twin_cycles. */
void twin_cycle_counts(const twin_t *twin, uint64_t *awake, uint64_t *asleep);

/* board_run_one_instruction_per_call: on (nonzero), simavr's default pace, for tests. */
void twin_run_one_instruction_per_call(twin_t *twin, int on);

/*
 * The sampling profiler (board_profile_start): a sample every period_cycles
 * awake cycles, up to capacity kept. Start returns 0, or -1 for a zero
 * period or capacity, or out of memory. Counts gives the samples taken and
 * those kept. Read copies up to max_samples kept samples, twin_profile_frames()
 * uint32 each (the PC, then the call sites innermost first, UINT32_MAX past
 * the last), into frames, and returns how many.
 */
int twin_profile_start(twin_t *twin, uint64_t period_cycles, size_t capacity);
void twin_profile_stop(twin_t *twin);
size_t twin_profile_frames(void);
void twin_profile_counts(const twin_t *twin, uint64_t *taken, size_t *kept);
size_t twin_profile_read(const twin_t *twin, uint32_t *frames, size_t max_samples);

/* SRAM bytes between the static data and RAMEND that the stack never reached; capacity gets their count. */
size_t twin_stack_untouched(const twin_t *twin, size_t *capacity);

/* These return 0, or -1 for a channel or fault out of range. */
int twin_adc_set_millivolts(twin_t *twin, unsigned channel, double millivolts);
/* OPEN: the NTC is missing and the 100 k reference pulls the pin to 5 V. SHORT: 0 V. */
int twin_adc_set_fault(twin_t *twin, unsigned channel, int fault);

/* The LSM9DS0 at 0x1D; attaching again does nothing. Faults: 0 none, 1 absent, 2 stuck (lsm9ds0.h). */
void twin_lsm9ds0_attach(twin_t *twin);
int twin_lsm9ds0_set(twin_t *twin, int16_t ax, int16_t ay, int16_t az, int16_t temperature_raw);
int twin_lsm9ds0_set_fault(twin_t *twin, int fault);
/* INT2_XM (data-ready) to D2: wired at attach; 0 cuts the wire, 1 mends it. */
int twin_lsm9ds0_wire_data_ready(twin_t *twin, int wired);

/* The L298N observer needs an ATmega2560; -1 on any other MCU. */
int twin_l298n_attach(twin_t *twin);
/* duty 0..1 since the last read, direction +1/-1/0, pwm 0..255; -1 if not attached. */
int twin_l298n_read(twin_t *twin, double *duty, int *direction, int *pwm);
int twin_l298n_set_disconnected(twin_t *twin, int disconnected);

#endif
