/*
 * A small Unity-compatible test framework, used by the offline build only when
 * no real Unity (ThrowTheSwitch) is available. It implements the subset of the
 * Unity API this project's tests use and prints Unity's line formats, so the
 * same test sources run unchanged under `pio test` with the real Unity.
 *
 * Output goes through UNITY_OUTPUT_CHAR/START/FLUSH/COMPLETE, which a
 * unity_config.h (UNITY_INCLUDE_CONFIG_H) may define, exactly as with Unity.
 */
#ifndef THERMOTILT_UNITY_FALLBACK_H
#define THERMOTILT_UNITY_FALLBACK_H

#define UNITY_FALLBACK 1

#ifdef UNITY_INCLUDE_CONFIG_H
#include "unity_config.h"
#endif

#include <stdint.h>
#include <setjmp.h>

#ifdef __cplusplus
extern "C" {
#endif

void setUp(void);
void tearDown(void);

typedef void (*UnityTestFunction)(void);

/* The run's state, its first two fields as in Unity's unity_internals.h:
 * test/unity_main.cpp and sim/avr_run read the running test's name there. */
struct UNITY_STORAGE_T {
    const char *TestFile;
    const char *CurrentTestName;
    int CurrentTestLineNumber;
    unsigned int NumberOfTests;
    unsigned int TestFailures;
    unsigned int TestIgnores;
    unsigned char CurrentTestFailed;
    unsigned char CurrentTestIgnored;
};
extern struct UNITY_STORAGE_T Unity;

void UnityBegin(const char *file);
int UnityEnd(void);
void UnityDefaultTestRun(UnityTestFunction func, const char *name, int line);
void UnityMessage(const char *message, int line);
void UnityFail(const char *message, int line);
void UnityIgnore(const char *message, int line);
void UnityAssertEqualInt(long expected, long actual, const char *message, int line);
void UnityAssertEqualUnsigned(unsigned long expected, unsigned long actual,
                              const char *message, int line);
void UnityAssertIntWithin(long delta, long expected, long actual, const char *message,
                          int line);
void UnityAssertCompare(long threshold, long actual, int wantGreater, const char *message,
                        int line);
void UnityAssertFloatWithin(float delta, float expected, float actual, const char *message,
                            int line);
void UnityAssertEqualString(const char *expected, const char *actual, const char *message,
                            int line);
void UnityAssertEqualMemory(const void *expected, const void *actual, unsigned int length,
                            const char *message, int line);
void UnityAssertTrue(int condition, const char *failText, const char *message, int line);

extern jmp_buf UnityAbortFrame;

#ifdef __cplusplus
}
#endif

#define UNITY_BEGIN() UnityBegin(__FILE__)
#define UNITY_END() UnityEnd()
#define RUN_TEST(func) UnityDefaultTestRun(func, #func, __LINE__)
#define TEST_PROTECT() (setjmp(UnityAbortFrame) == 0)

#define TEST_MESSAGE(message) UnityMessage((message), __LINE__)
#define TEST_FAIL_MESSAGE(message) UnityFail((message), __LINE__)
#define TEST_FAIL() UnityFail(0, __LINE__)
#define TEST_IGNORE_MESSAGE(message) UnityIgnore((message), __LINE__)
#define TEST_IGNORE() UnityIgnore(0, __LINE__)

#define TEST_ASSERT_MESSAGE(condition, message) \
    UnityAssertTrue((condition) ? 1 : 0, "Expression Evaluated To FALSE", (message), __LINE__)
#define TEST_ASSERT(condition) TEST_ASSERT_MESSAGE(condition, 0)
#define TEST_ASSERT_TRUE_MESSAGE(condition, message) TEST_ASSERT_MESSAGE(condition, message)
#define TEST_ASSERT_TRUE(condition) TEST_ASSERT_MESSAGE(condition, 0)
#define TEST_ASSERT_FALSE_MESSAGE(condition, message) \
    UnityAssertTrue((condition) ? 0 : 1, "Expected FALSE Was TRUE", (message), __LINE__)
#define TEST_ASSERT_FALSE(condition) TEST_ASSERT_FALSE_MESSAGE(condition, 0)
#define TEST_ASSERT_NULL(pointer) \
    UnityAssertTrue((pointer) == 0, "Expected NULL", 0, __LINE__)
#define TEST_ASSERT_NOT_NULL(pointer) \
    UnityAssertTrue((pointer) != 0, "Expected Non-NULL", 0, __LINE__)

#define TEST_ASSERT_EQUAL_INT_MESSAGE(e, a, m) \
    UnityAssertEqualInt((long)(e), (long)(a), (m), __LINE__)
#define TEST_ASSERT_EQUAL_INT(e, a) TEST_ASSERT_EQUAL_INT_MESSAGE(e, a, 0)
#define TEST_ASSERT_EQUAL(e, a) TEST_ASSERT_EQUAL_INT(e, a)
#define TEST_ASSERT_EQUAL_MESSAGE(e, a, m) TEST_ASSERT_EQUAL_INT_MESSAGE(e, a, m)
#define TEST_ASSERT_EQUAL_INT8(e, a) TEST_ASSERT_EQUAL_INT((int8_t)(e), (int8_t)(a))
#define TEST_ASSERT_EQUAL_INT16(e, a) TEST_ASSERT_EQUAL_INT((int16_t)(e), (int16_t)(a))
#define TEST_ASSERT_EQUAL_INT32(e, a) TEST_ASSERT_EQUAL_INT((int32_t)(e), (int32_t)(a))
#define TEST_ASSERT_EQUAL_INT16_MESSAGE(e, a, m) \
    TEST_ASSERT_EQUAL_INT_MESSAGE((int16_t)(e), (int16_t)(a), m)
#define TEST_ASSERT_EQUAL_INT32_MESSAGE(e, a, m) \
    TEST_ASSERT_EQUAL_INT_MESSAGE((int32_t)(e), (int32_t)(a), m)

#define TEST_ASSERT_EQUAL_UINT_MESSAGE(e, a, m) \
    UnityAssertEqualUnsigned((unsigned long)(e), (unsigned long)(a), (m), __LINE__)
#define TEST_ASSERT_EQUAL_UINT(e, a) TEST_ASSERT_EQUAL_UINT_MESSAGE(e, a, 0)
#define TEST_ASSERT_EQUAL_UINT8(e, a) TEST_ASSERT_EQUAL_UINT((uint8_t)(e), (uint8_t)(a))
#define TEST_ASSERT_EQUAL_UINT16(e, a) TEST_ASSERT_EQUAL_UINT((uint16_t)(e), (uint16_t)(a))
#define TEST_ASSERT_EQUAL_UINT32(e, a) TEST_ASSERT_EQUAL_UINT((uint32_t)(e), (uint32_t)(a))
#define TEST_ASSERT_EQUAL_HEX8(e, a) TEST_ASSERT_EQUAL_UINT8(e, a)
#define TEST_ASSERT_EQUAL_HEX16(e, a) TEST_ASSERT_EQUAL_UINT16(e, a)
#define TEST_ASSERT_EQUAL_HEX32(e, a) TEST_ASSERT_EQUAL_UINT32(e, a)
#define TEST_ASSERT_EQUAL_UINT8_MESSAGE(e, a, m) \
    TEST_ASSERT_EQUAL_UINT_MESSAGE((uint8_t)(e), (uint8_t)(a), m)
#define TEST_ASSERT_EQUAL_UINT16_MESSAGE(e, a, m) \
    TEST_ASSERT_EQUAL_UINT_MESSAGE((uint16_t)(e), (uint16_t)(a), m)
#define TEST_ASSERT_EQUAL_UINT32_MESSAGE(e, a, m) \
    TEST_ASSERT_EQUAL_UINT_MESSAGE((uint32_t)(e), (uint32_t)(a), m)
#define TEST_ASSERT_EQUAL_HEX8_MESSAGE(e, a, m) TEST_ASSERT_EQUAL_UINT8_MESSAGE(e, a, m)

#define TEST_ASSERT_INT_WITHIN_MESSAGE(d, e, a, m) \
    UnityAssertIntWithin((long)(d), (long)(e), (long)(a), (m), __LINE__)
#define TEST_ASSERT_INT_WITHIN(d, e, a) TEST_ASSERT_INT_WITHIN_MESSAGE(d, e, a, 0)
#define TEST_ASSERT_GREATER_THAN(threshold, actual) \
    UnityAssertCompare((long)(threshold), (long)(actual), 1, 0, __LINE__)
#define TEST_ASSERT_LESS_THAN(threshold, actual) \
    UnityAssertCompare((long)(threshold), (long)(actual), 0, 0, __LINE__)

#define TEST_ASSERT_FLOAT_WITHIN_MESSAGE(d, e, a, m) \
    UnityAssertFloatWithin((float)(d), (float)(e), (float)(a), (m), __LINE__)
#define TEST_ASSERT_FLOAT_WITHIN(d, e, a) TEST_ASSERT_FLOAT_WITHIN_MESSAGE(d, e, a, 0)

#define TEST_ASSERT_EQUAL_STRING_MESSAGE(e, a, m) \
    UnityAssertEqualString((e), (a), (m), __LINE__)
#define TEST_ASSERT_EQUAL_STRING(e, a) TEST_ASSERT_EQUAL_STRING_MESSAGE(e, a, 0)
#define TEST_ASSERT_EQUAL_MEMORY_MESSAGE(e, a, len, m) \
    UnityAssertEqualMemory((e), (a), (len), (m), __LINE__)
#define TEST_ASSERT_EQUAL_MEMORY(e, a, len) TEST_ASSERT_EQUAL_MEMORY_MESSAGE(e, a, len, 0)

#endif
