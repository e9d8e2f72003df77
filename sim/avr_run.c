/*
 * Runs one firmware image in simavr and copies its USART0 output to stdout.
 *
 *   avr_run -m atmega328p -f 16000000 [-t SECONDS] [--unity [--min-stack BYTES]]
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
 *
 * Every --unity run ends with a line of the image's RAM: its static data
 * (.data, .bss, .noinit) and how much of the SRAM above it the stack never
 * reached (board_stack_untouched). With --min-stack, a run that left fewer
 * untouched bytes fails even where its tests passed: on a Nano the stack
 * meeting static data is a crash that only sometimes shows.
 *
 * A run that restarts (the C runtime's start-up sets SP to RAMEND a second
 * time: a jump to the reset vector, or a reset) stops there and fails. A
 * restart, a crash or a time-out names the Unity test that was running, read
 * from Unity's state in SRAM.
 */
#include <ctype.h>
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
    EXIT_STACK_SHORT = 5,
    EXIT_RESTARTED = 6,
    LINE_CAPACITY = 256,
    MAX_ADC_INPUTS = 16,
    INPUT_CAPACITY = 64 * 1024,
    INPUT_START_MS = 200,
    TEST_NAME_CAPACITY = 80,
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

typedef struct {
    uint16_t unity; /* Unity's state (the symbol Unity), or 0 */
    int starts;
    char test[TEST_NAME_CAPACITY];
} start_watch_t;

/*
 * The name of the test Unity is running: Unity.CurrentTestName, the second
 * pointer of its state in both Unity and cmake/unity. Empty when there is no
 * such state or the pointer does not lead to a name (the crash overwrote it).
 */
static void running_test(const avr_t *avr, uint16_t unity, char *name)
{
    name[0] = '\0';
    if (unity == 0) {
        return;
    }
    uint16_t address = (uint16_t)(avr->data[unity + 2] | avr->data[unity + 3] << 8);
    for (size_t i = 0; i + 1 < TEST_NAME_CAPACITY && address + i <= avr->ramend; ++i) {
        char c = (char)avr->data[address + i];
        if (c == '\0') {
            memcpy(name, avr->data + address, i);
            name[i] = '\0';
            return;
        }
        if (!isalnum((unsigned char)c) && c != '_') {
            return;
        }
    }
}

enum { OPCODE_OUT_MASK = 0xF800, OPCODE_OUT = 0xB800 };

/*
 * SPL's writes. avr-libc's start-up code sets SP to RAMEND with an OUT, and
 * nothing else does: returns to the start-up code (from a constructor) pop
 * SP back to RAMEND, but with a RET.
 */
static void on_stack_pointer_low(avr_t *avr, avr_io_addr_t addr, uint8_t value, void *param)
{
    start_watch_t *watch = (start_watch_t *)param;
    avr->data[addr] = value;
    uint16_t opcode = (uint16_t)(avr->flash[avr->pc] | avr->flash[avr->pc + 1] << 8);
    if ((opcode & OPCODE_OUT_MASK) != OPCODE_OUT || (uint16_t)(value | avr->data[addr + 1] << 8) != avr->ramend ||
        ++watch->starts < 2) {
        return;
    }
    /* .bss is cleared only after this: the name is still the crashed run's. */
    running_test(avr, watch->unity, watch->test);
    avr->state = cpu_Done;
}

static const char *test_named(const char *name)
{
    return name[0] ? name : "an unknown test";
}

static int usage(void)
{
    fprintf(stderr, "usage: avr_run -m MCU -f HZ [-t SECONDS] [--unity [--min-stack BYTES]]"
                    " [--lsm9ds0 AX,AY,AZ,TEMP_RAW] [--adc CHANNEL=MILLIVOLTS]... [--input FILE] firmware.elf\n");
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

/* Prints the RAM line; returns 0 when at least min_untouched bytes were never reached by the stack. */
static int report_ram(const board_t *board, const char *elf_path, size_t min_untouched)
{
    size_t free_bytes = 0;
    size_t untouched = board_stack_untouched(board, &free_bytes);
    if (free_bytes == 0) {
        fprintf(stderr, "avr_run: %s has no _end symbol: its stack cannot be measured\n", elf_path);
        return min_untouched == 0 ? 0 : -1;
    }
    size_t ram_start = (size_t)board->avr->ioend + 1;
    size_t ram = (size_t)board->avr->ramend + 1 - ram_start;
    printf("avr_run: RAM %zu B: static %zu B, stack untouched %zu B\n", ram, ram - free_bytes, untouched);
    if (untouched < min_untouched) {
        fprintf(stderr, "avr_run: %s left %zu B of stack untouched, fewer than the %zu B required\n", elf_path,
                untouched, min_untouched);
        return -1;
    }
    return 0;
}

int main(int argc, char **argv)
{
    const char *mcu = NULL, *elf_path = NULL, *input_path = NULL;
    sensor_option_t sensor_option = {0};
    adc_options_t adc = {0};
    static uint8_t input[INPUT_CAPACITY];
    double frequency = 0, timeout_s = 60, min_stack = 0;
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
        } else if (strcmp(arg, "--min-stack") == 0 && has_value) {
            if (parse_positive(argv[++i], &min_stack) != 0)
                return usage();
        } else if (strcmp(arg, "--unity") == 0) {
            unity_mode = 1;
        } else if (arg[0] != '-' && !elf_path) {
            elf_path = arg;
        } else {
            return usage();
        }
    }
    if (!mcu || !elf_path || frequency <= 0 || (min_stack > 0 && !unity_mode)) {
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
    start_watch_t starts = {.unity = board_data_symbol(&board, "Unity")};
    avr_register_io_write(board.avr, R_SPL, on_stack_pointer_low, &starts);

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
    if (watch.length > 0) {
        putchar('\n');
    }
    int stack_ok = !unity_mode || report_ram(&board, elf_path, (size_t)min_stack) == 0;
    char test[TEST_NAME_CAPACITY];
    if (starts.starts > 1) {
        fprintf(stderr, "avr_run: %s restarted during %s after %.3f s simulated\n", elf_path, test_named(starts.test),
                simulated_s);
        return EXIT_RESTARTED;
    }
    if (state == cpu_Crashed) {
        running_test(board.avr, starts.unity, test);
        fprintf(stderr, "avr_run: %s crashed during %s after %.3f s simulated\n", elf_path, test_named(test),
                simulated_s);
        return EXIT_CRASHED;
    }
    if (!unity_mode) {
        return state == cpu_Done ? EXIT_PASSED : EXIT_TIMED_OUT;
    }
    if (!watch.verdict_seen) {
        running_test(board.avr, starts.unity, test);
        fprintf(stderr, "avr_run: %s printed no Unity verdict within %.1f s simulated, last in %s\n", elf_path,
                simulated_s, test_named(test));
        return EXIT_TIMED_OUT;
    }
    if (!(watch.verdict_ok && watch.failures == 0)) {
        return EXIT_TESTS_FAILED;
    }
    return stack_ok ? EXIT_PASSED : EXIT_STACK_SHORT;
}
