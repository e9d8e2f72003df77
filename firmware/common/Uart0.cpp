#include "Uart0.h"

#include <avr/interrupt.h>
#include <avr/io.h>
#include <util/atomic.h>

#if defined(USART0_RX_vect)
#define UART0_RECEIVED_VECTOR USART0_RX_vect
#define UART0_DATA_REGISTER_EMPTY_VECTOR USART0_UDRE_vect
#else
#define UART0_RECEIVED_VECTOR USART_RX_vect
#define UART0_DATA_REGISTER_EMPTY_VECTOR USART_UDRE_vect
#endif

namespace {

const uint8_t RING_MASK = Uart0::RING_SIZE - 1;
// Arduino's SERIAL_8N1.
const uint8_t EIGHT_DATA_BITS_NO_PARITY_ONE_STOP = (1 << UCSZ01) | (1 << UCSZ00);

inline __attribute__((always_inline)) uint8_t nextIndex(uint8_t index)
{
    return (uint8_t)((index + 1) & RING_MASK);
}

uint8_t received[Uart0::RING_SIZE];
uint8_t transmitted[Uart0::RING_SIZE];
volatile uint8_t receivedHead = 0;
volatile uint8_t receivedTail = 0;
volatile uint8_t transmittedHead = 0;
volatile uint8_t transmittedTail = 0;
// flush() has nothing to wait for before the first byte: TXC is only set
// by a transmission.
bool written = false;

inline __attribute__((always_inline)) void onReceived()
{
    if (UCSR0A & (1 << UPE0)) {
        (void)UDR0;
        return;
    }
    uint8_t value = UDR0;
    uint8_t head = receivedHead;
    uint8_t next = nextIndex(head);
    if (next != receivedTail) {
        received[head] = value;
        receivedHead = next;
    }
}

// Writing UDR0 and clearing TXC together, so flush() cannot see the
// previous byte's TXC after this one was queued.
inline __attribute__((always_inline)) void onDataRegisterEmpty()
{
    uint8_t tail = transmittedTail;
    UDR0 = transmitted[tail];
    tail = nextIndex(tail);
    transmittedTail = tail;
    UCSR0A = (uint8_t)((UCSR0A & ((1 << U2X0) | (1 << MPCM0))) | (1 << TXC0));
    if (transmittedHead == tail) {
        UCSR0B &= (uint8_t) ~(1 << UDRIE0);
    }
}

// With interrupts off nothing would empty the ring: do the interrupt's work.
void serviceWithInterruptsOff()
{
    if (!(SREG & (1 << SREG_I)) && (UCSR0B & (1 << UDRIE0)) && (UCSR0A & (1 << UDRE0))) {
        onDataRegisterEmpty();
    }
}

}  // namespace

ISR(UART0_RECEIVED_VECTOR)
{
    onReceived();
}

ISR(UART0_DATA_REGISTER_EMPTY_VECTOR)
{
    onDataRegisterEmpty();
}

void Uart0::begin(uint32_t baud)
{
    // HardwareSerial::begin's setting: double speed, except 57600 at 16 MHz
    // (the old bootloaders' rate) and rates too slow for it.
    uint16_t setting = (uint16_t)((F_CPU / 4 / baud - 1) / 2);
    UCSR0A = 1 << U2X0;
    if ((F_CPU == 16000000UL && baud == 57600) || setting > 4095) {
        UCSR0A = 0;
        setting = (uint16_t)((F_CPU / 8 / baud - 1) / 2);
    }
    UBRR0H = (uint8_t)(setting >> 8);
    UBRR0L = (uint8_t)setting;
    written = false;
    UCSR0C = EIGHT_DATA_BITS_NO_PARITY_ONE_STOP;
    UCSR0B = (1 << RXEN0) | (1 << TXEN0) | (1 << RXCIE0);
}

uint8_t Uart0::available()
{
    return (uint8_t)((receivedHead - receivedTail) & RING_MASK);
}

int Uart0::read()
{
    uint8_t tail = receivedTail;
    if (tail == receivedHead) {
        return -1;
    }
    uint8_t value = received[tail];
    receivedTail = nextIndex(tail);
    return value;
}

uint8_t Uart0::availableForWrite()
{
    return (uint8_t)(RING_MASK - ((transmittedHead - transmittedTail) & RING_MASK));
}

void Uart0::write(const char* bytes, uint8_t count)
{
    written = true;
    uint8_t head = transmittedHead;
    while (count > 0) {
        uint8_t next = nextIndex(head);
        if (next == transmittedTail) {
            ATOMIC_BLOCK(ATOMIC_RESTORESTATE)
            {
                UCSR0B |= 1 << UDRIE0;
            }
            serviceWithInterruptsOff();
            continue;
        }
        transmitted[head] = (uint8_t)*bytes++;
        head = next;
        transmittedHead = head;
        --count;
    }
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE)
    {
        UCSR0B |= 1 << UDRIE0;
    }
}

void Uart0::flush()
{
    if (!written) {
        return;
    }
    while ((UCSR0B & (1 << UDRIE0)) || !(UCSR0A & (1 << TXC0))) {
        serviceWithInterruptsOff();
    }
}
