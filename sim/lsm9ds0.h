/*
 * LSM9DS0 accelerometer/magnetometer (XM) die as an I2C slave: the register
 * file the firmware sees, data produced at the rate CTRL_REG1_XM selects,
 * STATUS_REG_A data-ready flags, and auto-increment reads. Acceleration and
 * temperature come from whoever drives the model (lsm9ds0_set_*), faults
 * from lsm9ds0_set_fault.
 */
#ifndef THERMOTILT_SIM_LSM9DS0_H
#define THERMOTILT_SIM_LSM9DS0_H

#include <stdint.h>

#include <simavr/sim_avr.h>
#include <simavr/sim_irq.h>

/* After the TWI pair: INT2_XM's level (data-ready when P2_DRDYA is set). */
enum { LSM9DS0_IRQ_INT2 = 2, LSM9DS0_IRQ_COUNT = 3 };
/* INT2_XM is wired to the Nano's D2 (PD2, INT0), as in the README. */
#define LSM9DS0_INT2_PORT 'D'
#define LSM9DS0_INT2_BIT 2

typedef struct lsm9ds0 {
    avr_t *avr;
    avr_irq_t *irq; /* [TWI_IRQ_INPUT] to the AVR, [TWI_IRQ_OUTPUT] from it, [LSM9DS0_IRQ_INT2] */
    uint32_t int2_level;
    uint8_t int2_wired;
    uint8_t address;
    uint8_t registers[128];
    uint8_t selected;
    uint8_t pointer;
    uint8_t auto_increment;
    uint8_t expecting_pointer;
    int16_t acceleration[3];
    int16_t temperature_raw;
    uint8_t absent; /* no ACK, as an unplugged sensor */
    uint8_t stuck;  /* answers, but its sample clock has stopped */
} lsm9ds0_t;

typedef enum lsm9ds0_fault {
    LSM9DS0_FAULT_NONE = 0,
    LSM9DS0_FAULT_ABSENT = 1,
    LSM9DS0_FAULT_STUCK = 2,
} lsm9ds0_fault_t;

enum { LSM9DS0_ADDRESS_SDO_HIGH = 0x1D };

void lsm9ds0_init(avr_t *avr, lsm9ds0_t *sensor, uint8_t address7);
/* On the TWI bus, with INT2_XM wired to D2. */
void lsm9ds0_attach(lsm9ds0_t *sensor);
/* Connects INT2_XM to D2 or cuts the wire (D2 then reads its pull-up, high). */
void lsm9ds0_wire_int2(lsm9ds0_t *sensor, int wired);
/*
 * The MCU was reset (a board_reset_fn, so context is the sensor): simavr
 * dropped the sample clock's timer, which the sensor keeps running, with its
 * registers, through a reset of the MCU.
 */
void lsm9ds0_mcu_reset(void *context);

void lsm9ds0_set_acceleration(lsm9ds0_t *sensor, int16_t x, int16_t y, int16_t z);
/* 12-bit two's complement, 8 LSB/degC, as OUT_TEMP_L/H_XM report it. */
void lsm9ds0_set_temperature_raw(lsm9ds0_t *sensor, int16_t raw);

/*
 * ABSENT: no address or data byte is acknowledged from now on.
 * STUCK: registers still read and write, but the outputs stay frozen and
 * STATUS_REG_A reports no new data once the last sample was read.
 * NONE: back to normal; the sample clock resumes at the configured rate.
 */
void lsm9ds0_set_fault(lsm9ds0_t *sensor, lsm9ds0_fault_t fault);

#endif
