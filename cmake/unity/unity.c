#include "unity.h"

#include <string.h>

#ifndef UNITY_OUTPUT_CHAR
#include <stdio.h>
#define UNITY_OUTPUT_CHAR(c) (void)putchar(c)
#endif
#ifndef UNITY_OUTPUT_START
#define UNITY_OUTPUT_START()
#endif
#ifndef UNITY_OUTPUT_FLUSH
#define UNITY_OUTPUT_FLUSH()
#endif
#ifndef UNITY_OUTPUT_COMPLETE
#define UNITY_OUTPUT_COMPLETE()
#endif

jmp_buf UnityAbortFrame;

struct UNITY_STORAGE_T Unity;

static void printString(const char *text)
{
    while (text && *text) {
        UNITY_OUTPUT_CHAR(*text++);
    }
}

static void printUnsigned(unsigned long value)
{
    char digits[11];
    int count = 0;
    do {
        digits[count++] = (char)('0' + value % 10u);
        value /= 10u;
    } while (value != 0u);
    while (count > 0) {
        UNITY_OUTPUT_CHAR(digits[--count]);
    }
}

static void printSigned(long value)
{
    if (value < 0) {
        UNITY_OUTPUT_CHAR('-');
        printUnsigned(0ul - (unsigned long)value);
    } else {
        printUnsigned((unsigned long)value);
    }
}

/* Six significant digits in scientific notation: enough to read a failure. */
static void printFloat(float value)
{
    if (value != value) {
        printString("nan");
        return;
    }
    if (value < 0.0f) {
        UNITY_OUTPUT_CHAR('-');
        value = -value;
    }
    if (value > 3.4e38f) {
        printString("inf");
        return;
    }
    int exponent = 0;
    if (value != 0.0f) {
        while (value >= 10.0f) {
            value /= 10.0f;
            exponent++;
        }
        while (value < 1.0f) {
            value *= 10.0f;
            exponent--;
        }
    }
    unsigned long mantissa = (unsigned long)(value * 100000.0f + 0.5f);
    if (mantissa >= 1000000ul) {
        mantissa /= 10ul;
        exponent++;
    }
    printUnsigned(mantissa / 100000ul);
    UNITY_OUTPUT_CHAR('.');
    unsigned long fraction = mantissa % 100000ul;
    for (unsigned long scale = 10000ul; scale > 0ul; scale /= 10ul) {
        UNITY_OUTPUT_CHAR((char)('0' + (fraction / scale) % 10ul));
    }
    UNITY_OUTPUT_CHAR('e');
    printSigned(exponent);
}

static void printLocation(int line)
{
    printString(Unity.TestFile);
    UNITY_OUTPUT_CHAR(':');
    printSigned(line);
    UNITY_OUTPUT_CHAR(':');
    printString(Unity.CurrentTestName);
    UNITY_OUTPUT_CHAR(':');
}

static void printMessageTail(const char *message)
{
    if (message) {
        printString(" ");
        printString(message);
    }
    UNITY_OUTPUT_CHAR('\n');
}

static void failHeader(int line)
{
    printLocation(line);
    printString("FAIL: ");
}

static void abortTest(void)
{
    Unity.CurrentTestFailed = 1;
    longjmp(UnityAbortFrame, 1);
}

void UnityBegin(const char *file)
{
    UNITY_OUTPUT_START();
    Unity.TestFile = file;
    Unity.NumberOfTests = 0;
    Unity.TestFailures = 0;
    Unity.TestIgnores = 0;
}

int UnityEnd(void)
{
    printString("\n-----------------------\n");
    printUnsigned(Unity.NumberOfTests);
    printString(" Tests ");
    printUnsigned(Unity.TestFailures);
    printString(" Failures ");
    printUnsigned(Unity.TestIgnores);
    printString(" Ignored \n");
    printString(Unity.TestFailures == 0 ? "OK\n" : "FAIL\n");
    UNITY_OUTPUT_FLUSH();
    UNITY_OUTPUT_COMPLETE();
    return (int)Unity.TestFailures;
}

void UnityDefaultTestRun(UnityTestFunction func, const char *name, int line)
{
    Unity.CurrentTestName = name;
    Unity.CurrentTestLineNumber = line;
    Unity.CurrentTestFailed = 0;
    Unity.CurrentTestIgnored = 0;
    Unity.NumberOfTests++;
    if (TEST_PROTECT()) {
        setUp();
        func();
    }
    if (TEST_PROTECT()) {
        tearDown();
    }
    if (Unity.CurrentTestIgnored) {
        Unity.TestIgnores++;
    } else if (Unity.CurrentTestFailed) {
        Unity.TestFailures++;
    } else {
        printLocation(line);
        printString("PASS\n");
    }
    UNITY_OUTPUT_FLUSH();
}

void UnityMessage(const char *message, int line)
{
    printLocation(line);
    printString("INFO: ");
    printString(message);
    UNITY_OUTPUT_CHAR('\n');
}

void UnityFail(const char *message, int line)
{
    failHeader(line);
    printString(message ? message : "Fail");
    UNITY_OUTPUT_CHAR('\n');
    abortTest();
}

void UnityIgnore(const char *message, int line)
{
    printLocation(line);
    printString("IGNORE");
    if (message) {
        printString(": ");
        printString(message);
    }
    UNITY_OUTPUT_CHAR('\n');
    Unity.CurrentTestIgnored = 1;
    longjmp(UnityAbortFrame, 1);
}

void UnityAssertTrue(int condition, const char *failText, const char *message, int line)
{
    if (condition) {
        return;
    }
    failHeader(line);
    printString(failText);
    printMessageTail(message);
    abortTest();
}

void UnityAssertEqualInt(long expected, long actual, const char *message, int line)
{
    if (expected == actual) {
        return;
    }
    failHeader(line);
    printString("Expected ");
    printSigned(expected);
    printString(" Was ");
    printSigned(actual);
    printMessageTail(message);
    abortTest();
}

void UnityAssertEqualUnsigned(unsigned long expected, unsigned long actual,
                              const char *message, int line)
{
    if (expected == actual) {
        return;
    }
    failHeader(line);
    printString("Expected ");
    printUnsigned(expected);
    printString(" Was ");
    printUnsigned(actual);
    printMessageTail(message);
    abortTest();
}

void UnityAssertIntWithin(long delta, long expected, long actual, const char *message,
                          int line)
{
    long difference = actual > expected ? actual - expected : expected - actual;
    if (difference <= delta) {
        return;
    }
    failHeader(line);
    printString("Values Not Within Delta ");
    printSigned(delta);
    printString(" Expected ");
    printSigned(expected);
    printString(" Was ");
    printSigned(actual);
    printMessageTail(message);
    abortTest();
}

void UnityAssertCompare(long threshold, long actual, int wantGreater, const char *message,
                        int line)
{
    if (wantGreater ? actual > threshold : actual < threshold) {
        return;
    }
    failHeader(line);
    printString("Expected ");
    printString(wantGreater ? "greater than " : "less than ");
    printSigned(threshold);
    printString(" Was ");
    printSigned(actual);
    printMessageTail(message);
    abortTest();
}

void UnityAssertFloatWithin(float delta, float expected, float actual, const char *message,
                            int line)
{
    float difference = actual > expected ? actual - expected : expected - actual;
    if (difference <= delta) {
        return;
    }
    failHeader(line);
    printString("Values Not Within Delta ");
    printFloat(delta);
    printString(" Expected ");
    printFloat(expected);
    printString(" Was ");
    printFloat(actual);
    printMessageTail(message);
    abortTest();
}

void UnityAssertEqualString(const char *expected, const char *actual, const char *message,
                            int line)
{
    if (expected && actual && strcmp(expected, actual) == 0) {
        return;
    }
    if (!expected && !actual) {
        return;
    }
    failHeader(line);
    printString("Expected '");
    printString(expected ? expected : "NULL");
    printString("' Was '");
    printString(actual ? actual : "NULL");
    UNITY_OUTPUT_CHAR('\'');
    printMessageTail(message);
    abortTest();
}

void UnityAssertEqualMemory(const void *expected, const void *actual, unsigned int length,
                            const char *message, int line)
{
    const unsigned char *want = (const unsigned char *)expected;
    const unsigned char *got = (const unsigned char *)actual;
    for (unsigned int index = 0; index < length; index++) {
        if (want[index] != got[index]) {
            failHeader(line);
            printString("Memory Mismatch at byte ");
            printUnsigned(index);
            printString(" Expected ");
            printUnsigned(want[index]);
            printString(" Was ");
            printUnsigned(got[index]);
            printMessageTail(message);
            abortTest();
        }
    }
}
