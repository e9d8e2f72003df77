#include "l298n.h"

#include <string.h>

#include <simavr/sim_io.h>

/* ATmega2560 data-space addresses and bits (datasheet, register summary). */
enum {
    TCCR2A = 0xB0,
    TCCR2B = 0xB1,
    OCR2B = 0xB4,
    DDRH = 0x101,
    PORTH = 0x102,
    COM2B1 = 5,
    COM2B0 = 4,
    WGM22 = 3,
    WGM21 = 1,
    WGM20 = 0,
    ENA_BIT = 6,
    IN1_BIT = 4,
    IN2_BIT = 3,
    WGM_PHASE_CORRECT_TOP_FF = 1,
    WGM_FAST_PWM_TOP_FF = 3,
};

/*
 * Duty in units that make both 8-bit PWM kinds exact integers: phase-correct
 * is high for OCR/255 of the period, fast PWM for (OCR+1)/256.
 */
enum { L298N_FULL_LEVEL = 255 * 256 };

static uint8_t bit_of(uint8_t value, int bit)
{
    return (uint8_t)((value >> bit) & 1u);
}

static uint8_t waveform_mode(const avr_t *avr)
{
    return (uint8_t)((bit_of(avr->data[TCCR2B], WGM22) << 2) | (bit_of(avr->data[TCCR2A], WGM21) << 1) |
                     bit_of(avr->data[TCCR2A], WGM20));
}

static int pwm_connected(const avr_t *avr)
{
    uint8_t mode = waveform_mode(avr);
    return bit_of(avr->data[TCCR2A], COM2B1) && (mode == WGM_PHASE_CORRECT_TOP_FF || mode == WGM_FAST_PWM_TOP_FF);
}

/* ENA's level as a fraction of L298N_FULL_LEVEL. */
static uint32_t enable_level(const avr_t *avr)
{
    if (!bit_of(avr->data[DDRH], ENA_BIT)) {
        return 0;
    }
    if (!pwm_connected(avr)) {
        return bit_of(avr->data[PORTH], ENA_BIT) ? L298N_FULL_LEVEL : 0;
    }
    uint32_t ocr = avr->data[OCR2B];
    uint32_t level = waveform_mode(avr) == WGM_PHASE_CORRECT_TOP_FF ? ocr * 256u : (ocr + 1u) * 255u;
    /* COM2B0 set as well selects the inverted output. */
    return bit_of(avr->data[TCCR2A], COM2B0) ? L298N_FULL_LEVEL - level : level;
}

static uint8_t commanded_pwm(const avr_t *avr)
{
    if (!bit_of(avr->data[DDRH], ENA_BIT)) {
        return 0;
    }
    if (bit_of(avr->data[TCCR2A], COM2B1)) {
        return avr->data[OCR2B];
    }
    return bit_of(avr->data[PORTH], ENA_BIT) ? 255 : 0;
}

static uint8_t driven_high(const avr_t *avr, int bit)
{
    return bit_of(avr->data[DDRH], bit) && bit_of(avr->data[PORTH], bit);
}

static int8_t pin_direction(const avr_t *avr)
{
    uint8_t in1 = driven_high(avr, IN1_BIT);
    uint8_t in2 = driven_high(avr, IN2_BIT);
    if (in1 == in2) {
        return 0; /* both low: no current; both high: brake */
    }
    return in1 ? 1 : -1;
}

static void accumulate_until_now(l298n_t *bridge)
{
    avr_cycle_count_t now = bridge->avr->cycle;
    bridge->level_cycles += (uint64_t)bridge->level * (now - bridge->level_since);
    bridge->level_since = now;
}

static void update(l298n_t *bridge)
{
    accumulate_until_now(bridge);
    const avr_t *avr = bridge->avr;
    bridge->commanded_pwm = commanded_pwm(avr);
    bridge->pin_direction = pin_direction(avr);
    int current_flows = !bridge->disconnected && bridge->pin_direction != 0;
    bridge->level = current_flows ? enable_level(avr) : 0;
}

static void on_register_write(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    (void)value;
    update((l298n_t *)param);
}

void l298n_attach(l298n_t *bridge, avr_t *avr)
{
    static const avr_io_addr_t watched[] = {TCCR2A, TCCR2B, OCR2B, DDRH, PORTH};
    memset(bridge, 0, sizeof *bridge);
    bridge->avr = avr;
    bridge->level_since = avr->cycle;
    bridge->window_start = avr->cycle;
    for (size_t i = 0; i < sizeof watched / sizeof watched[0]; i++) {
        avr_irq_register_notify(avr_iomem_getirq(avr, watched[i], NULL, AVR_IOMEM_IRQ_ALL), on_register_write, bridge);
    }
    update(bridge);
}

void l298n_read(l298n_t *bridge, l298n_drive_t *drive)
{
    accumulate_until_now(bridge);
    avr_cycle_count_t window = bridge->level_since - bridge->window_start;
    if (window == 0) {
        drive->duty = (double)bridge->level / L298N_FULL_LEVEL;
    } else {
        drive->duty = (double)bridge->level_cycles / ((double)L298N_FULL_LEVEL * (double)window);
    }
    drive->direction = bridge->disconnected ? 0 : bridge->pin_direction;
    drive->pwm = bridge->commanded_pwm;
    bridge->level_cycles = 0;
    bridge->window_start = bridge->level_since;
}

void l298n_set_disconnected(l298n_t *bridge, int disconnected)
{
    bridge->disconnected = disconnected != 0;
    update(bridge);
}
