/*
 * Runs one firmware image in simavr and copies its USART0 output to stdout.
 *
 *   avr_run -m atmega328p -f 16000000 [-t SECONDS] [--unity]
 *           [--lsm9ds0 AX,AY,AZ,TEMP_RAW] [--adc CHANNEL=MILLIVOLTS]...
 *           [--input FILE] firmware.elf
 *
 * --lsm9ds0 attaches a simulated LSM9DS0 at 0x1D holding a constant
 * acceleration (LSB) and raw temperature; --adc holds an analog input at a
 * voltage; --input sends a file's bytes to USART0 from 200 ms on.
 *
 * The simavr command line always exits 0; this runner exits with a status a
 * build can trust. With --unity it reads Unity's summary ("N Tests N Failures
 * N Ignored" then OK/FAIL), stops the simulation there, and exits 0 only for
 * a run that printed OK with zero failures.
 */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "board.h"
#include "lsm9ds0.h"

enum {
    EXIT_PASSED = 0,
    EXIT_TESTS_FAILED = 1,
    EXIT_USAGE = 2,
    EXIT_CRASHED = 3,
    EXIT_TIMED_OUT = 4,
    LINE_CAPACITY = 256,
    MAX_ADC_INPUTS = 16,
    INPUT_CAPACITY = 64 * 1024,
    INPUT_START_MS = 200,
};

typedef struct {
    int attached;
    int values[4];
} sensor_option_t;

typedef struct {
    int count;
    int channel[MAX_ADC_INPUTS];
    int millivolts[MAX_ADC_INPUTS];
} adc_options_t;

typedef struct {
    char line[LINE_CAPACITY];
    size_t length;
    int saw_summary;
    long failures;
    int verdict_ok;
    int verdict_seen;
} unity_watch_t;

static void watch_line(unity_watch_t *watch)
{
    long tests = 0, failures = 0, ignored = 0;
    if (sscanf(watch->line, "%ld Tests %ld Failures %ld Ignored", &tests, &failures, &ignored) == 3) {
        watch->saw_summary = 1;
        watch->failures = failures;
    } else if (watch->saw_summary && (strcmp(watch->line, "OK") == 0 || strcmp(watch->line, "FAIL") == 0)) {
        watch->verdict_seen = 1;
        watch->verdict_ok = strcmp(watch->line, "OK") == 0;
    }
}

static void on_uart_byte(void *context, uint8_t byte)
{
    unity_watch_t *watch = (unity_watch_t *)context;
    putchar(byte);
    if (byte == '\r') {
        return;
    }
    if (byte == '\n') {
        watch->line[watch->length] = '\0';
        watch_line(watch);
        watch->length = 0;
    } else if (watch->length + 1 < LINE_CAPACITY) {
        watch->line[watch->length++] = (char)byte;
    }
}

static int usage(void)
{
    fprintf(stderr, "usage: avr_run -m MCU -f HZ [-t SECONDS] [--unity] [--lsm9ds0 AX,AY,AZ,TEMP_RAW]"
                    " [--adc CHANNEL=MILLIVOLTS]... [--input FILE] firmware.elf\n");
    return EXIT_USAGE;
}

static int parse_sensor(const char *text, sensor_option_t *sensor)
{
    int consumed = 0;
    if (sscanf(text, "%d,%d,%d,%d%n", &sensor->values[0], &sensor->values[1], &sensor->values[2], &sensor->values[3],
               &consumed) != 4 ||
        text[consumed] != '\0') {
        return -1;
    }
    sensor->attached = 1;
    return 0;
}

static int parse_adc(const char *text, adc_options_t *adc)
{
    int channel = 0, millivolts = 0, consumed = 0;
    if (adc->count >= MAX_ADC_INPUTS || sscanf(text, "%d=%d%n", &channel, &millivolts, &consumed) != 2 ||
        text[consumed] != '\0' || channel < 0 || channel > 15 || millivolts < 0) {
        return -1;
    }
    adc->channel[adc->count] = channel;
    adc->millivolts[adc->count] = millivolts;
    adc->count++;
    return 0;
}

static long read_input(const char *path, uint8_t *buffer)
{
    FILE *file = fopen(path, "rb");
    if (!file) {
        fprintf(stderr, "avr_run: cannot read input '%s'\n", path);
        return -1;
    }
    size_t length = fread(buffer, 1, INPUT_CAPACITY, file);
    int too_long = fgetc(file) != EOF;
    fclose(file);
    if (too_long) {
        fprintf(stderr, "avr_run: input '%s' is over %d bytes\n", path, INPUT_CAPACITY);
        return -1;
    }
    return (long)length;
}

static int parse_positive(const char *text, double *out)
{
    char *end = NULL;
    errno = 0;
    double value = strtod(text, &end);
    if (errno != 0 || end == text || *end != '\0' || value <= 0) {
        return -1;
    }
    *out = value;
    return 0;
}

int main(int argc, char **argv)
{
    const char *mcu = NULL, *elf_path = NULL, *input_path = NULL;
    sensor_option_t sensor_option = {0};
    adc_options_t adc = {0};
    static uint8_t input[INPUT_CAPACITY];
    double frequency = 0, timeout_s = 60;
    int unity_mode = 0;
    for (int i = 1; i < argc; i++) {
        const char *arg = argv[i];
        int has_value = i + 1 < argc;
        if (strcmp(arg, "-m") == 0 && has_value) {
            mcu = argv[++i];
        } else if (strcmp(arg, "-f") == 0 && has_value) {
            if (parse_positive(argv[++i], &frequency) != 0)
                return usage();
        } else if (strcmp(arg, "-t") == 0 && has_value) {
            if (parse_positive(argv[++i], &timeout_s) != 0)
                return usage();
        } else if (strcmp(arg, "--lsm9ds0") == 0 && has_value) {
            if (parse_sensor(argv[++i], &sensor_option) != 0)
                return usage();
        } else if (strcmp(arg, "--adc") == 0 && has_value) {
            if (parse_adc(argv[++i], &adc) != 0)
                return usage();
        } else if (strcmp(arg, "--input") == 0 && has_value) {
            input_path = argv[++i];
        } else if (strcmp(arg, "--unity") == 0) {
            unity_mode = 1;
        } else if (arg[0] != '-' && !elf_path) {
            elf_path = arg;
        } else {
            return usage();
        }
    }
    if (!mcu || !elf_path || frequency <= 0) {
        return usage();
    }

    board_t board;
    char error[256];
    if (board_load(&board, elf_path, mcu, (uint32_t)frequency, error, sizeof error) != 0) {
        fprintf(stderr, "%s\n", error);
        return EXIT_USAGE;
    }
    unity_watch_t watch;
    memset(&watch, 0, sizeof watch);
    board_capture_uart0(&board, on_uart_byte, &watch);

    lsm9ds0_t sensor;
    if (sensor_option.attached) {
        lsm9ds0_init(board.avr, &sensor, LSM9DS0_ADDRESS_SDO_HIGH);
        lsm9ds0_set_acceleration(&sensor, (int16_t)sensor_option.values[0], (int16_t)sensor_option.values[1],
                                 (int16_t)sensor_option.values[2]);
        lsm9ds0_set_temperature_raw(&sensor, (int16_t)sensor_option.values[3]);
        lsm9ds0_attach(&sensor);
    }
    for (int i = 0; i < adc.count; i++) {
        board_set_adc_millivolts(&board, (uint8_t)adc.channel[i], (uint32_t)adc.millivolts[i]);
    }
    if (input_path) {
        long length = read_input(input_path, input);
        if (length < 0) {
            return EXIT_USAGE;
        }
        board_feed_uart0(&board, input, (size_t)length, INPUT_START_MS);
    }

    uint64_t max_cycles = (uint64_t)(timeout_s * frequency);
    int state = cpu_Running;
    /* Run in slices so a Unity run that never stops the CPU still ends at its verdict. */
    uint64_t slice = (uint64_t)(frequency / 100);
    while (board.avr->cycle < max_cycles && !watch.verdict_seen) {
        uint64_t until = board.avr->cycle + slice;
        state = board_run(&board, until < max_cycles ? until : max_cycles);
        if (state == cpu_Done || state == cpu_Crashed) {
            break;
        }
    }
    fflush(stdout);

    double simulated_s = (double)board.avr->cycle / frequency;
    if (state == cpu_Crashed) {
        fprintf(stderr, "avr_run: %s crashed after %.3f s simulated\n", elf_path, simulated_s);
        return EXIT_CRASHED;
    }
    if (!unity_mode) {
        return state == cpu_Done ? EXIT_PASSED : EXIT_TIMED_OUT;
    }
    if (!watch.verdict_seen) {
        fprintf(stderr, "avr_run: %s printed no Unity verdict within %.1f s simulated\n", elf_path, simulated_s);
        return EXIT_TIMED_OUT;
    }
    return watch.verdict_ok && watch.failures == 0 ? EXIT_PASSED : EXIT_TESTS_FAILED;
}
