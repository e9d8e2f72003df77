#include "twin.h"

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "board.h"
#include "l298n.h"
#include "lsm9ds0.h"
#include "uart_bridge.h"

/*
 * The pty is polled between slices of this length, so a client sees answers
 * during a long run_until; 10 ms is the lockstep period anyway.
 */
enum { PTY_POLLS_PER_SECOND = 100 };

struct twin {
    board_t board;
    uart_bridge_t uart;
    double adc_millivolts[TWIN_ADC_CHANNELS];
    uint8_t adc_fault[TWIN_ADC_CHANNELS];
    int sensor_attached;
    lsm9ds0_t sensor;
    int l298n_attached;
    l298n_t l298n;
};

/*
 * simavr prints progress ("Loaded 16314 .text ...") on stdout, which belongs
 * to the host program using this library; only its errors go out, to stderr.
 * The logger is global to simavr, as is this library's use of it.
 */
static void log_errors_only(avr_t *avr, const int level, const char *format, va_list arguments)
{
    (void)avr;
    if (level <= LOG_ERROR) {
        vfprintf(stderr, format, arguments);
    }
}

twin_t *twin_create(const char *elf_path, const char *mcu, uint32_t frequency_hz, char *error, size_t error_capacity)
{
    avr_global_logger_set(log_errors_only);
    twin_t *twin = calloc(1, sizeof *twin);
    if (!twin) {
        if (error_capacity > 0) {
            snprintf(error, error_capacity, "twin: out of memory");
        }
        return NULL;
    }
    if (board_load(&twin->board, elf_path, mcu, frequency_hz, error, error_capacity) != 0) {
        free(twin);
        return NULL;
    }
    uart_bridge_attach(&twin->uart, &twin->board);
    return twin;
}

void twin_free(twin_t *twin)
{
    if (!twin) {
        return;
    }
    uart_bridge_free(&twin->uart);
    board_free(&twin->board);
    free(twin);
}

int twin_run_until(twin_t *twin, uint64_t until_cycle)
{
    avr_t *avr = twin->board.avr;
    uint64_t slice = avr->frequency / PTY_POLLS_PER_SECOND;
    int state = avr->state;
    while (avr->cycle < until_cycle) {
        uart_bridge_poll_pty(&twin->uart);
        uint64_t slice_end = until_cycle;
        if (twin->uart.pty_master >= 0 && until_cycle - avr->cycle > slice) {
            slice_end = avr->cycle + slice;
        }
        state = board_run(&twin->board, slice_end);
        if (state == cpu_Done || state == cpu_Crashed) {
            break;
        }
    }
    uart_bridge_poll_pty(&twin->uart);
    if (state == cpu_Crashed) {
        return TWIN_CRASHED;
    }
    return state == cpu_Done ? TWIN_DONE : TWIN_RUNNING;
}

uint64_t twin_cycles(const twin_t *twin)
{
    return twin->board.avr->cycle;
}

size_t twin_uart_pending(const twin_t *twin)
{
    return uart_bridge_pending(&twin->uart);
}

size_t twin_uart_read(twin_t *twin, uint8_t *out, size_t capacity)
{
    return uart_bridge_read(&twin->uart, out, capacity);
}

int twin_uart_write(twin_t *twin, const uint8_t *bytes, size_t length)
{
    return uart_bridge_write(&twin->uart, bytes, length);
}

const char *twin_uart_open_pty(twin_t *twin)
{
    return uart_bridge_open_pty(&twin->uart);
}

void twin_uart_set_corruption(twin_t *twin, double probability, uint64_t seed)
{
    uart_bridge_set_corruption(&twin->uart, probability, seed);
}

uint64_t twin_uart_corrupted_bytes(const twin_t *twin)
{
    return twin->uart.noise[0].corrupted_bytes + twin->uart.noise[1].corrupted_bytes;
}

uint64_t twin_pty_dropped_bytes(const twin_t *twin)
{
    return twin->uart.pty_dropped_bytes;
}

static void apply_adc(twin_t *twin, unsigned channel)
{
    double millivolts = twin->adc_millivolts[channel];
    if (twin->adc_fault[channel] == TWIN_ADC_OPEN) {
        millivolts = TWIN_SUPPLY_MILLIVOLTS;
    } else if (twin->adc_fault[channel] == TWIN_ADC_SHORT) {
        millivolts = 0;
    }
    board_set_adc_millivolts(&twin->board, (uint8_t)channel, millivolts);
}

size_t twin_eeprom_size(const twin_t *twin)
{
    return board_eeprom_size(&twin->board);
}

int twin_eeprom_read(twin_t *twin, size_t offset, uint8_t *out, size_t length)
{
    return board_eeprom_read(&twin->board, offset, out, length);
}

int twin_eeprom_write(twin_t *twin, size_t offset, const uint8_t *bytes, size_t length)
{
    return board_eeprom_write(&twin->board, offset, bytes, length);
}

void twin_cycle_counts(const twin_t *twin, uint64_t *awake, uint64_t *asleep)
{
    board_cycle_counts(&twin->board, awake, asleep);
}

void twin_run_one_instruction_per_call(twin_t *twin, int on)
{
    board_run_one_instruction_per_call(&twin->board, on);
}

int twin_profile_start(twin_t *twin, uint64_t period_cycles, size_t capacity)
{
    return board_profile_start(&twin->board, period_cycles, capacity);
}

void twin_profile_stop(twin_t *twin)
{
    board_profile_stop(&twin->board);
}

size_t twin_profile_frames(void)
{
    return BOARD_PROFILE_FRAMES;
}

void twin_profile_counts(const twin_t *twin, uint64_t *taken, size_t *kept)
{
    *taken = twin->board.profile.taken;
    *kept = twin->board.profile.kept;
}

size_t twin_profile_read(const twin_t *twin, uint32_t *frames, size_t max_samples)
{
    const board_profile_t *profile = &twin->board.profile;
    size_t count = profile->kept < max_samples ? profile->kept : max_samples;
    if (count > 0) {
        memcpy(frames, profile->samples, count * sizeof *profile->samples);
    }
    return count;
}

size_t twin_stack_untouched(const twin_t *twin, size_t *capacity)
{
    return board_stack_untouched(&twin->board, capacity);
}

int twin_hang(twin_t *twin)
{
    return board_hang(&twin->board);
}

int twin_adc_set_millivolts(twin_t *twin, unsigned channel, double millivolts)
{
    if (channel >= TWIN_ADC_CHANNELS) {
        return -1;
    }
    twin->adc_millivolts[channel] = millivolts;
    apply_adc(twin, channel);
    return 0;
}

int twin_adc_set_fault(twin_t *twin, unsigned channel, int fault)
{
    if (channel >= TWIN_ADC_CHANNELS || fault < TWIN_ADC_NONE || fault > TWIN_ADC_SHORT) {
        return -1;
    }
    twin->adc_fault[channel] = (uint8_t)fault;
    apply_adc(twin, channel);
    return 0;
}

void twin_lsm9ds0_attach(twin_t *twin)
{
    if (twin->sensor_attached) {
        return;
    }
    lsm9ds0_init(twin->board.avr, &twin->sensor, LSM9DS0_ADDRESS_SDO_HIGH);
    lsm9ds0_attach(&twin->sensor);
    board_on_reset(&twin->board, lsm9ds0_mcu_reset, &twin->sensor);
    twin->sensor_attached = 1;
}

int twin_lsm9ds0_set(twin_t *twin, int16_t ax, int16_t ay, int16_t az, int16_t temperature_raw)
{
    if (!twin->sensor_attached) {
        return -1;
    }
    lsm9ds0_set_acceleration(&twin->sensor, ax, ay, az);
    lsm9ds0_set_temperature_raw(&twin->sensor, temperature_raw);
    return 0;
}

int twin_lsm9ds0_set_fault(twin_t *twin, int fault)
{
    if (!twin->sensor_attached || fault < LSM9DS0_FAULT_NONE || fault > LSM9DS0_FAULT_STUCK) {
        return -1;
    }
    lsm9ds0_set_fault(&twin->sensor, (lsm9ds0_fault_t)fault);
    return 0;
}

int twin_lsm9ds0_wire_data_ready(twin_t *twin, int wired)
{
    if (!twin->sensor_attached) {
        return -1;
    }
    lsm9ds0_wire_int2(&twin->sensor, wired);
    return 0;
}

int twin_l298n_attach(twin_t *twin)
{
    if (strcmp(twin->board.avr->mmcu, "atmega2560") != 0) {
        return -1;
    }
    if (!twin->l298n_attached) {
        l298n_attach(&twin->l298n, twin->board.avr);
        twin->l298n_attached = 1;
    }
    return 0;
}

int twin_l298n_read(twin_t *twin, double *duty, int *direction, int *pwm)
{
    if (!twin->l298n_attached) {
        return -1;
    }
    l298n_drive_t drive;
    l298n_read(&twin->l298n, &drive);
    *duty = drive.duty;
    *direction = drive.direction;
    *pwm = drive.pwm;
    return 0;
}

int twin_l298n_set_disconnected(twin_t *twin, int disconnected)
{
    if (!twin->l298n_attached) {
        return -1;
    }
    l298n_set_disconnected(&twin->l298n, disconnected);
    return 0;
}
