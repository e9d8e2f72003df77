/* libthermotilt_host.so: single algorithms of the firmware's libraries, each
 * over arrays of count inputs, compiled for the host from the same sources.
 * The host keeps Python copies of some (a scenario's staircase, the physics
 * model's trend, set blend and drift surfaces); host/tests/test_firmware_differential.py
 * checks each copy against them. The chamber's drive law has no copy: the
 * physics tests that close the loop around the chamber model call it. Each returns 0, or
 * THERMOTILT_HOST_BAD_ARGUMENT (a NULL array with count > 0) and writes
 * nothing then. */
#ifndef THERMOTILT_HOST_FIRMWARE_ALGORITHMS_H
#define THERMOTILT_HOST_FIRMWARE_ALGORITHMS_H

#include <stddef.h>
#include <stdint.h>

#include "imu_processing.h"

#ifdef __cplusplus
extern "C" {
#endif

/* lib/Program: TemperatureProgram::configure of the staircase start_c[i],
 * max_c[i], step_c[i] with a 1 s hold, no rest, endless cycles and timed
 * holds (settings that pass every check but the staircase's own). error[i]:
 * its ProgramError (0 accepted); steps_per_cycle[i]: stepsPerCycle() if
 * accepted, else 0. */
int thermotilt_program_steps(size_t count, const float *start_c, const float *max_c, const float *step_c,
                             uint8_t *error, uint16_t *steps_per_cycle);

/* lib/Compensation: one TrendDetector(hysteresis_c), starting warming, fed
 * temperature_c in order; set[i] is what update(temperature_c[i]) returned,
 * 0 warming, 1 cooling. */
int thermotilt_trend_sets(size_t count, const float *temperature_c, float hysteresis_c, uint8_t *set);

/* lib/Compensation: one SetBlend(transition_c), starting warming, fed
 * temperature_c in order; share[i] is what update(temperature_c[i])
 * returned, the warming share 0..1. */
int thermotilt_set_blend_shares(size_t count, const float *temperature_c, float transition_c, float *share);

/* lib/Compensation: surfaceCorrection f(T, a) of the surface p (p00, p10,
 * p01, p20, p11, p02) at T = temperature_c[i], a = accel_lsb[i]. */
int thermotilt_surface_corrections(size_t count, const float *p, const float *temperature_c, const float *accel_lsb,
                                   float *correction);

/* lib/Compensation: encodeCoefficients of 36 coefficients in block order,
 * a domain of 16 int16 (set W, C x temperature min, max in 1/100 degC, then
 * acceleration min, max in LSB of X, Y, Z) and the NUL-terminated
 * sensor_id, into block (188 bytes). THERMOTILT_HOST_BAD_ARGUMENT for an ID
 * isValidSensorId refuses. */
int thermotilt_coefficient_block_encode(const float *coefficients, const int16_t *domain, const char *sensor_id,
                                        uint8_t *block);

/* lib/Compensation: decodeCoefficients of block (188 bytes) on a board
 * whose ID is board_sensor_id; *status is its BlockStatus (0 Ok, 1 Blank,
 * 2 BadMagic, 3 BadVersion, 4 BadCrc, 5 BadValues, 6 OtherSensor).
 * coefficients (36) and domain (16, as above) hold what the call leaves in
 * them: the block's on Ok, what they held before otherwise. */
int thermotilt_coefficient_block_decode(const uint8_t *block, const char *board_sensor_id, uint8_t *status,
                                        float *coefficients, int16_t *domain);

/* lib/Compensation: isValidSensorId of each of count NUL-terminated texts
 * (texts[i]); valid[i] is 1 or 0. */
int thermotilt_sensor_ids_valid(size_t count, const char *const *texts, uint8_t *valid);

/* lib/ChamberControl: one ChamberController(proportional_gain,
 * integral_gain), rounded error on or off, updated with setpoint_c[i] and
 * measured_c[i] every dt_s in order; pwm[i] and direction[i] (0 off, 1 heat,
 * 2 cool) are what update returned. */
int thermotilt_chamber_drive(size_t count, const float *setpoint_c, const float *measured_c, float dt_s,
                             float proportional_gain, float integral_gain, uint8_t rounded_error, uint8_t *pwm,
                             uint8_t *direction);

#ifdef __cplusplus
}
#endif

#endif
