// USART0, the board's USB serial port, run from its interrupts as Arduino's
// HardwareSerial runs it (the same speed setting, 8N1, 64-byte receive and
// transmit rings, a byte with a parity error dropped, a full receive ring
// dropping what comes), but cheaper per byte: a frame is copied into the
// transmit ring in one loop instead of one virtual write() a byte, the
// interrupts save only the registers they use, and the ring indices are
// 8-bit masks instead of int modulo. HardwareSerial cost the IMU reader
// some 270 cycles a byte sent; no reachable library does this. SerialLink
// is its only user, on both boards.
#ifndef THERMOTILT_UART0_H
#define THERMOTILT_UART0_H

#include <stdint.h>

class Uart0 {
public:
    // Either ring holds one byte less than its size, as HardwareSerial's.
    static const uint8_t RING_SIZE = 64;

    static void begin(uint32_t baud);
    // Bytes received and not read yet.
    static uint8_t available();
    // The next byte received, or -1.
    static int read();
    // How many bytes write() takes without waiting.
    static uint8_t availableForWrite();
    // Queues the bytes, waiting for room where the ring is full.
    static void write(const char* bytes, uint8_t count);
    // Waits until every byte written has left the line.
    static void flush();
};

#endif
