/*
 * Runs one firmware image in simavr and copies its USART0 output to stdout.
 *
 *   avr_run -m atmega328p -f 16000000 [-t SECONDS] [--unity] firmware.elf
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

enum {
    EXIT_PASSED = 0,
    EXIT_TESTS_FAILED = 1,
    EXIT_USAGE = 2,
    EXIT_CRASHED = 3,
    EXIT_TIMED_OUT = 4,
    LINE_CAPACITY = 256,
};

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
    fprintf(stderr, "usage: avr_run -m MCU -f HZ [-t SECONDS] [--unity] firmware.elf\n");
    return EXIT_USAGE;
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
    const char *mcu = NULL, *elf_path = NULL;
    double frequency = 0, timeout_s = 60;
    int unity_mode = 0;
    for (int i = 1; i < argc; i++) {
        const char *arg = argv[i];
        int has_value = i + 1 < argc;
        if (strcmp(arg, "-m") == 0 && has_value) {
            mcu = argv[++i];
        } else if (strcmp(arg, "-f") == 0 && has_value) {
            if (parse_positive(argv[++i], &frequency) != 0) return usage();
        } else if (strcmp(arg, "-t") == 0 && has_value) {
            if (parse_positive(argv[++i], &timeout_s) != 0) return usage();
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
    if (board_load(&board, elf_path, mcu, (uint32_t)frequency) != 0) {
        return EXIT_USAGE;
    }
    unity_watch_t watch;
    memset(&watch, 0, sizeof watch);
    board_capture_uart0(&board, on_uart_byte, &watch);

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
        fprintf(stderr, "avr_run: %s printed no Unity verdict within %.1f s simulated\n", elf_path,
                simulated_s);
        return EXIT_TIMED_OUT;
    }
    return watch.verdict_ok && watch.failures == 0 ? EXIT_PASSED : EXIT_TESTS_FAILED;
}
