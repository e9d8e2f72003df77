/* libthermotilt_host.so: the IMU reader's per-sample processing
 * (lib/ImuProcessing, with lib/Kalman, lib/Compensation and lib/LSM9DS0's
 * temperatureRawToC) compiled for the host, run over a whole series. Loaded
 * by host/thermotilt/native.py through ctypes.
 *
 * Every series starts as the firmware starts streaming after it found the
 * sensor: filters unseeded, trend warming with no sample, decimation count 0.
 * For sample i, reset[i] != 0 first does what RESEED does (filters forget
 * their state, the decimation count restarts, the trend is kept); then the
 * sample is processed and counted towards a frame (the firmware streaming).
 *
 * Arrays: accel and the filtered/compensated outputs are count x 3, row major
 * (X, Y, Z of a sample next to each other); the others hold count values.
 * reset may be NULL (no resets). coefficients: 36 float32 in the EEPROM
 * block's order, set (warming, cooling) x axis (X, Y, Z) x term (p00, p10,
 * p01, p20, p11, p02), or NULL for the firmware's defaults. compensated is
 * written for every sample with the sets blended as far as the sensor has
 * crossed then (lib/Compensation SetBlend); the firmware computes
 * it only where frame_due[i] is 1, with the same function and inputs.
 * set[i]: 0 warming, 1 cooling. at: NULL, or at_count sample indices in
 * order (repeats allowed); then only those samples are written, sample at[k]
 * to output row k (the outputs hold at_count rows), every sample still
 * processed. Returns 0, or THERMOTILT_HOST_BAD_ARGUMENT
 * (a NULL array with count > 0, decimation outside 1..255, hysteresis not
 * finite, at out of order or beyond count) and writes nothing then. */
#ifndef THERMOTILT_HOST_IMU_PROCESSING_H
#define THERMOTILT_HOST_IMU_PROCESSING_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define THERMOTILT_HOST_ABI_VERSION 7
#define THERMOTILT_HOST_BAD_ARGUMENT (-1)

int thermotilt_host_abi_version(void);

/* The firmware's path: raw LSB as the LSM9DS0's registers hold them and
 * OUT_TEMP_XM raw (8 LSB/degC; the firmware adds 21 degC). */
int thermotilt_imu_process(size_t count, const int16_t *accel, const int16_t *temperature_raw, const uint8_t *reset,
                           unsigned decimation, float hysteresis_c, const float *coefficients, const size_t *at,
                           size_t at_count, float *filtered, float *temperature_c, uint8_t *set, float *compensated,
                           uint8_t *frame_due);

/* The same processing from unquantised inputs: acceleration in LSB and the
 * sensor's temperature in degC (what temperatureRawToC would give, before
 * the filter), as float32. On integer LSB and temperatures raw/8 + 21 it
 * gives exactly what thermotilt_imu_process gives. */
int thermotilt_imu_process_unrounded(size_t count, const float *accel, const float *temperature_c_in,
                                     const uint8_t *reset, unsigned decimation, float hysteresis_c,
                                     const float *coefficients, const size_t *at, size_t at_count, float *filtered,
                                     float *temperature_c, uint8_t *set, float *compensated, uint8_t *frame_due);

/* One channel of thermotilt_imu_process_unrounded: the Kalman filter
 * lib/ImuProcessing runs per axis and for the temperature, over count float32
 * measurements, reset[i] != 0 seeding it again at sample i (reset may be
 * NULL). estimates[k] is the filter's estimate after sample at[k] (at as
 * there; NULL: every sample, estimates holding count values) - the same
 * float as that function's filtered value or temperature_c for the channel.
 * Returns 0, or THERMOTILT_HOST_BAD_ARGUMENT (a NULL array with values to
 * read or write, at out of order or beyond count) and writes nothing then. */
int thermotilt_kalman_estimates(size_t count, const float *measurements, const uint8_t *reset, const size_t *at,
                                size_t at_count, float *estimates);

#ifdef __cplusplus
}
#endif

#endif
