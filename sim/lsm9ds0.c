#include "lsm9ds0.h"

#include <string.h>

#include <simavr/avr_ioport.h>
#include <simavr/avr_twi.h>
#include <simavr/sim_cycle_timers.h>

/* Register names and fields as in the LSM9DS0 datasheet. */
enum {
    OUT_TEMP_L_XM = 0x05,
    OUT_TEMP_H_XM = 0x06,
    WHO_AM_I_XM = 0x0F,
    INT_CTRL_REG_M = 0x12,
    CTRL_REG1_XM = 0x20,
    CTRL_REG4_XM = 0x23,
    CTRL_REG5_XM = 0x24,
    STATUS_REG_A = 0x27,
    OUT_X_L_A = 0x28,
    OUT_Z_H_A = 0x2D,
    WHO_AM_I_XM_VALUE = 0x49,
    SUB_ADDRESS_AUTO_INCREMENT = 0x80,
    TEMP_EN = 0x80,
    ZYXADA = 0x08,
    ZYXAOR = 0x80,
    P2_DRDYA = 0x08,
    IEA = 0x08,
    /* Datasheet reset value: XMIEN, YMIEN, ZMIEN and IEA set. */
    INT_CTRL_REG_M_RESET = 0xE8,
};

/* AODR[3:0] of CTRL_REG1_XM -> output data rate in mHz (0 = power-down). */
static const uint32_t output_rate_mhz[16] = {0,      3125,   6250,   12500,  25000,  50000,
                                             100000, 200000, 400000, 800000, 1600000};

static uint8_t data_rate_index(const lsm9ds0_t *sensor)
{
    return (uint8_t)(sensor->registers[CTRL_REG1_XM] >> 4);
}

/*
 * INT2_XM with P2_DRDYA: data-ready as a level, active while ZYXADA is set.
 * The model takes IEA set as active-high; the firmware learns the polarity
 * rather than relying on it (lib/LSM9DS0, DataReadyLine).
 */
static void update_int2(lsm9ds0_t *sensor)
{
    int active = (sensor->registers[CTRL_REG4_XM] & P2_DRDYA) && (sensor->registers[STATUS_REG_A] & ZYXADA);
    int active_high = (sensor->registers[INT_CTRL_REG_M] & IEA) != 0;
    uint32_t level = (uint32_t)(active ? active_high : !active_high);
    if (level != sensor->int2_level) {
        sensor->int2_level = level;
        avr_raise_irq(sensor->irq + LSM9DS0_IRQ_INT2, level);
    }
}

static void store_sample(lsm9ds0_t *sensor)
{
    uint8_t enabled_axes = sensor->registers[CTRL_REG1_XM] & 0x07;
    for (int axis = 0; axis < 3; axis++) {
        if (enabled_axes & (1u << axis)) {
            uint16_t value = (uint16_t)sensor->acceleration[axis];
            sensor->registers[OUT_X_L_A + 2 * axis] = (uint8_t)(value & 0xFF);
            sensor->registers[OUT_X_L_A + 2 * axis + 1] = (uint8_t)(value >> 8);
        }
    }
    if (sensor->registers[CTRL_REG5_XM] & TEMP_EN) {
        uint16_t raw = (uint16_t)sensor->temperature_raw & 0x0FFF;
        sensor->registers[OUT_TEMP_L_XM] = (uint8_t)(raw & 0xFF);
        sensor->registers[OUT_TEMP_H_XM] = (uint8_t)(raw >> 8);
    }
    uint8_t status = sensor->registers[STATUS_REG_A];
    if (status & ZYXADA) {
        status |= ZYXAOR;
    }
    sensor->registers[STATUS_REG_A] = (uint8_t)(status | ZYXADA | enabled_axes);
    update_int2(sensor);
}

/* Runs every 1/ODR; at power-down it polls every millisecond for a new rate. */
static avr_cycle_count_t produce_sample(avr_t *avr, avr_cycle_count_t when, void *param)
{
    lsm9ds0_t *sensor = (lsm9ds0_t *)param;
    uint32_t rate_mhz = output_rate_mhz[data_rate_index(sensor)];
    if (rate_mhz == 0) {
        return when + avr->frequency / 1000;
    }
    if (!sensor->stuck) {
        store_sample(sensor);
    }
    return when + (avr_cycle_count_t)((uint64_t)avr->frequency * 1000u / rate_mhz);
}

static uint8_t read_register(lsm9ds0_t *sensor, uint8_t reg)
{
    uint8_t value = sensor->registers[reg & 0x7F];
    /* Reading the last output byte hands the sample over: new data clears. */
    if (reg == OUT_Z_H_A) {
        sensor->registers[STATUS_REG_A] = 0;
        update_int2(sensor);
    }
    return value;
}

static void reply(lsm9ds0_t *sensor, uint8_t condition, uint8_t data)
{
    avr_raise_irq(sensor->irq + TWI_IRQ_INPUT, avr_twi_irq_msg(condition, sensor->selected, data));
}

static void on_twi_message(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    lsm9ds0_t *sensor = (lsm9ds0_t *)param;
    avr_twi_msg_irq_t message;
    message.u.v = value;

    if (sensor->absent) {
        sensor->selected = 0;
        return;
    }
    if (message.u.twi.msg & TWI_COND_STOP) {
        sensor->selected = 0;
    }
    if (message.u.twi.msg & TWI_COND_START) {
        sensor->selected = 0;
        if ((message.u.twi.addr >> 1) == sensor->address) {
            sensor->selected = message.u.twi.addr;
            /* A write starts with the register pointer; a repeated-start read keeps it. */
            sensor->expecting_pointer = (message.u.twi.addr & 1) == 0;
            reply(sensor, TWI_COND_ACK, 1);
        }
    }
    if (!sensor->selected) {
        return;
    }
    if (message.u.twi.msg & TWI_COND_WRITE) {
        reply(sensor, TWI_COND_ACK, 1);
        uint8_t data = message.u.twi.data;
        if (sensor->expecting_pointer) {
            sensor->pointer = data & 0x7F;
            sensor->auto_increment = (data & SUB_ADDRESS_AUTO_INCREMENT) != 0;
            sensor->expecting_pointer = 0;
        } else if (sensor->pointer != WHO_AM_I_XM && sensor->pointer != STATUS_REG_A) {
            sensor->registers[sensor->pointer] = data;
            update_int2(sensor);
            if (sensor->auto_increment) {
                sensor->pointer = (sensor->pointer + 1) & 0x7F;
            }
        }
    }
    if (message.u.twi.msg & TWI_COND_READ) {
        uint8_t data = read_register(sensor, sensor->pointer);
        if (sensor->auto_increment) {
            sensor->pointer = (sensor->pointer + 1) & 0x7F;
        }
        reply(sensor, TWI_COND_READ, data);
    }
}

static const char *irq_names[LSM9DS0_IRQ_COUNT] = {
    [TWI_IRQ_INPUT] = "8>lsm9ds0.out",
    [TWI_IRQ_OUTPUT] = "32<lsm9ds0.in",
    [LSM9DS0_IRQ_INT2] = ">lsm9ds0.int2_xm",
};

void lsm9ds0_init(avr_t *avr, lsm9ds0_t *sensor, uint8_t address7)
{
    memset(sensor, 0, sizeof *sensor);
    sensor->avr = avr;
    sensor->address = address7;
    sensor->registers[WHO_AM_I_XM] = WHO_AM_I_XM_VALUE;
    /* CTRL_REG1_XM resets to 0x07: power-down with all axes enabled. */
    sensor->registers[CTRL_REG1_XM] = 0x07;
    sensor->registers[INT_CTRL_REG_M] = INT_CTRL_REG_M_RESET;
    sensor->irq = avr_alloc_irq(&avr->irq_pool, 0, LSM9DS0_IRQ_COUNT, irq_names);
    avr_irq_register_notify(sensor->irq + TWI_IRQ_OUTPUT, on_twi_message, sensor);
    avr_cycle_timer_register(avr, avr->frequency / 1000, produce_sample, sensor);
}

void lsm9ds0_mcu_reset(void *context)
{
    lsm9ds0_t *sensor = (lsm9ds0_t *)context;
    avr_cycle_timer_register(sensor->avr, sensor->avr->frequency / 1000, produce_sample, sensor);
}

void lsm9ds0_attach(lsm9ds0_t *sensor)
{
    avr_t *avr = sensor->avr;
    avr_connect_irq(sensor->irq + TWI_IRQ_INPUT, avr_io_getirq(avr, AVR_IOCTL_TWI_GETIRQ(0), TWI_IRQ_INPUT));
    avr_connect_irq(avr_io_getirq(avr, AVR_IOCTL_TWI_GETIRQ(0), TWI_IRQ_OUTPUT), sensor->irq + TWI_IRQ_OUTPUT);
    sensor->int2_level = (sensor->registers[INT_CTRL_REG_M] & IEA) ? 0 : 1;
    sensor->int2_wired = 0;
    lsm9ds0_wire_int2(sensor, 1);
}

void lsm9ds0_wire_int2(lsm9ds0_t *sensor, int wired)
{
    avr_irq_t *pin = avr_io_getirq(sensor->avr, AVR_IOCTL_IOPORT_GETIRQ(LSM9DS0_INT2_PORT), LSM9DS0_INT2_BIT);
    wired = wired != 0;
    if (wired == sensor->int2_wired) {
        return;
    }
    sensor->int2_wired = (uint8_t)wired;
    if (wired) {
        avr_connect_irq(sensor->irq + LSM9DS0_IRQ_INT2, pin);
        avr_raise_irq(pin, sensor->int2_level);
    } else {
        avr_unconnect_irq(sensor->irq + LSM9DS0_IRQ_INT2, pin);
        /* The firmware's pull-up holds a pin that nothing drives high. */
        avr_raise_irq(pin, 1);
    }
}

void lsm9ds0_set_acceleration(lsm9ds0_t *sensor, int16_t x, int16_t y, int16_t z)
{
    sensor->acceleration[0] = x;
    sensor->acceleration[1] = y;
    sensor->acceleration[2] = z;
}

void lsm9ds0_set_temperature_raw(lsm9ds0_t *sensor, int16_t raw)
{
    sensor->temperature_raw = raw;
}

void lsm9ds0_set_fault(lsm9ds0_t *sensor, lsm9ds0_fault_t fault)
{
    sensor->absent = fault == LSM9DS0_FAULT_ABSENT;
    sensor->stuck = fault == LSM9DS0_FAULT_STUCK;
}
