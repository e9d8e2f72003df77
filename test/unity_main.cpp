// Compiled into every test program (PlatformIO builds C/C++ files at the root
// of test/ together with each test), so each test file only defines
// runUnityTests() and runs unchanged natively and on the boards.
int runUnityTests(void);

#ifdef ARDUINO
#include <Arduino.h>
#include <unity.h>

// A program whose stack runs into its static data may jump back to the reset
// vector and start its tests again, for ever: to a runner that looks like a
// slow run. The marker below outlives such a restart (.noinit, which the C
// runtime leaves alone), so the program fails the test it was in instead.
namespace {

// Power-on RAM holds these four bytes by chance once in 2^32 boots.
const uint32_t TESTS_RUNNING = 0x54547552UL;

struct RestartWatch {
    uint32_t marker;
    const char* testName;
};
RestartWatch restartWatch __attribute__((section(".noinit")));

extern "C" char __data_start;
extern "C" char __data_end;

// A test's name is a string literal, so it lies in .data; a pointer that the
// stack overwrote does not name a test.
bool namesTest(const char* name)
{
    return name >= &__data_start && name < &__data_end;
}

// Its strings are copied from flash onto the stack: a program that restarts
// is one short of RAM, and these lines cost it no static data.
__attribute__((noinline)) void failRestarted(void)
{
    char message[40];
    strcpy_P(message, PSTR("the program restarted during this test"));
    TEST_FAIL_MESSAGE(message);
}

__attribute__((noinline)) void reportRestart(const char* name)
{
    char file[20];
    strcpy_P(file, PSTR("test/unity_main.cpp"));
    char unknown[13];
    strcpy_P(unknown, PSTR("unknown_test"));
    UnityBegin(file);
    UnityDefaultTestRun(failRestarted, namesTest(name) ? name : unknown, __LINE__);
    UNITY_END();
}

}  // namespace

// Runs before the C runtime copies .data and clears .bss (avr-libc's .init4),
// while Unity's record of the running test is still in RAM.
void keepRunningTestName() __attribute__((naked, used, section(".init3")));
void keepRunningTestName()
{
    if (restartWatch.marker == TESTS_RUNNING) {
        restartWatch.testName = Unity.CurrentTestName;
    }
}

void setup()
{
    if (restartWatch.marker == TESTS_RUNNING) {
        restartWatch.marker = 0;
        reportRestart(restartWatch.testName);
        return;
    }
    // A real board resets when the host opens its serial port; give the test
    // runner time to start listening before the first line is printed.
    delay(2000);
    restartWatch.marker = TESTS_RUNNING;
    runUnityTests();
    restartWatch.marker = 0;
}

void loop() {}
#else
int main()
{
#ifdef PIO_UNIT_TESTING
    // PlatformIO reads the verdict from Unity's lines and reports any
    // non-zero exit as a signal (1 = "SIGHUP"), an errored suite and an
    // extra failed case. CTest, in the offline build, needs the exit code.
    runUnityTests();
    return 0;
#else
    return runUnityTests() == 0 ? 0 : 1;
#endif
}
#endif
