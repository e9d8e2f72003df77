/*
 * The L298N bridge driving the Peltier cell, seen from the Arduino Mega's
 * pins (lib/ChamberControl): ENA = D9 = PH6 = OC2B (Timer2 channel B), IN1 =
 * D7 = PH4, IN2 = D6 = PH3. analogWrite(9, 1..254) connects OC2B to Timer2's
 * PWM; analogWrite(9, 0 or 255) disconnects it and sets the PORTH bit, so
 * the observer follows the timer registers and the pin levels together.
 *
 * Event-driven: every write to TCCR2A/B, OCR2B, DDRH or PORTH closes the
 * interval driven at the previous level, so the mean duty over a window in
 * which the drive is held is exact.
 */
#ifndef THERMOTILT_SIM_L298N_H
#define THERMOTILT_SIM_L298N_H

#include <stdint.h>

#include <simavr/sim_avr.h>

typedef struct l298n {
    avr_t *avr;
    uint8_t disconnected; /* fault hook: the Peltier wire is cut */
    uint8_t commanded_pwm;
    int8_t pin_direction;
    uint32_t level; /* what reaches the Peltier, in 1/L298N_FULL_LEVEL */
    avr_cycle_count_t level_since;
    avr_cycle_count_t window_start;
    uint64_t level_cycles; /* sum of level x cycles since window_start */
} l298n_t;

typedef struct l298n_drive {
    /* Mean fraction of time the Peltier carried current since the last read. */
    double duty;
    /* +1 heat (IN1 high, IN2 low), -1 cool (IN2 high, IN1 low), 0 no current. */
    int direction;
    /* Last value given to analogWrite(9, ...) as the registers show it, 0..255. */
    int pwm;
} l298n_drive_t;

/* Watches the pins of an ATmega2560 from now on. */
void l298n_attach(l298n_t *bridge, avr_t *avr);

/* Reports the drive since the previous read and starts a new window. */
void l298n_read(l298n_t *bridge, l298n_drive_t *drive);

/* A cut wire: the pins are still seen (pwm), but duty and direction are 0. */
void l298n_set_disconnected(l298n_t *bridge, int disconnected);

#endif
