// Compiled into every test program (PlatformIO builds C/C++ files at the root
// of test/ together with each test), so each test file only defines
// runUnityTests() and runs unchanged natively and on the boards.
int runUnityTests(void);

#ifdef ARDUINO
#include <Arduino.h>

void setup()
{
    // A real board resets when the host opens its serial port; give the test
    // runner time to start listening before the first line is printed.
    delay(2000);
    runUnityTests();
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
