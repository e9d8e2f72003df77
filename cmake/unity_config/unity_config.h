/*
 * Unity output for the offline build (used with the real Unity or the
 * fallback in cmake/unity). On the AVR, characters go to Arduino's Serial at
 * 115200 baud, and the end of the run stops the CPU, which
 * ends the simulation.
 */
#ifndef THERMOTILT_UNITY_CONFIG_H
#define THERMOTILT_UNITY_CONFIG_H

#ifdef __AVR__
#ifdef __cplusplus
extern "C" {
#endif
void unityOutputStart(void);
void unityOutputChar(char c);
void unityOutputComplete(void);
#ifdef __cplusplus
}
#endif
#define UNITY_OUTPUT_START() unityOutputStart()
#define UNITY_OUTPUT_CHAR(c) unityOutputChar(c)
#define UNITY_OUTPUT_COMPLETE() unityOutputComplete()
#endif

#endif
