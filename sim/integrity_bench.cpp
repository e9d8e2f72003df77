// `make bench`: how many corrupted frames the firmware's own parser accepts.
// Frames shaped like the ones on the wire (IMU and CHS from the boards,
// SETPRG and SETCOE from the host) go through the twin's wire fault
// (line_noise.c, one random bit flipped per corrupted byte) into
// FrameParser; an accepted frame whose type, SEQ or fields differ from what
// was sent is a corrupted frame taken for a good one.
//
// Usage: integrity_bench [frames per rate] [rate ...]
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <Protocol.h>

#include "line_noise.h"

namespace {

const uint64_t kDefaultFrames = 4000000;
const double kDefaultRates[] = {0.001, 0.01};
// With none seen in n trials, 3/n is the 95 % upper bound (-ln 0.05 = 3.0).
const double kZeroEventsUpperBound95 = 2.995732;

struct Draws {
    uint64_t state;
    uint32_t below(uint32_t limit) { return (uint32_t)(splitmix64_next(&state) % limit); }
    float between(float low, float high)
    {
        return low + (high - low) * (float)(splitmix64_next(&state) >> 11) * (1.0f / 9007199254740992.0f);
    }
};

// One frame of each kind the line carries, with values that change every time.
const char* makeFrame(FrameWriter& writer, uint16_t seq, Draws& draws)
{
    switch (draws.below(4)) {
    case 0:
        writer.begin(Protocol::Tag::IMU, seq);
        writer.addUnsigned(draws.below(100000000));
        for (int axis = 0; axis < 3; ++axis)
            writer.addInt((int32_t)draws.below(65536) - 32768);
        for (int axis = 0; axis < 6; ++axis)
            writer.addFixed(draws.between(-20000.0f, 20000.0f), 1);
        writer.addFixed(draws.between(-10.0f, 45.0f), 3);
        writer.addChar(draws.below(2) ? 'W' : 'C');
        writer.addChar('E');
        break;
    case 1:
        writer.begin(Protocol::Tag::CHS, seq);
        writer.addUnsigned(draws.below(100000000));
        writer.addChar('W');
        writer.addUnsigned(draws.below(57));
        writer.addFixed(draws.between(-10.0f, 45.0f), 2);
        writer.addFixed(draws.between(-10.0f, 45.0f), 2);
        writer.addFixed(draws.between(-10.0f, 45.0f), 2);
        writer.addUnsigned(draws.below(256));
        writer.addChar(draws.below(2) ? 'H' : 'C');
        writer.addText("OK");
        break;
    case 2:
        writer.begin(Protocol::Tag::SETPRG, seq);
        writer.addFixed(draws.between(-10.0f, 10.0f), 2);
        writer.addFixed(draws.between(30.0f, 45.0f), 2);
        writer.addFixed(draws.between(0.5f, 5.0f), 2);
        writer.addUnsigned(draws.below(600) + 1);
        writer.addUnsigned(draws.below(3600));
        writer.addUnsigned(draws.below(10));
        break;
    default:
        writer.begin(Protocol::Tag::SETCOE, seq);
        writer.addChar(draws.below(2) ? 'W' : 'C');
        writer.addChar((char)('X' + draws.below(3)));
        for (int term = 0; term < 6; ++term)
            writer.addScientific(draws.between(-600.0f, 600.0f), 9);
        break;
    }
    return writer.finish();
}

// The frame as the parser holds it, rejoined: TYPE,SEQ,fields.
void rejoin(const FrameParser& parser, char* out, size_t capacity)
{
    int written = snprintf(out, capacity, "%s,%u", parser.type(), (unsigned)parser.seq());
    for (uint8_t i = 0; i < parser.fieldCount() && written > 0 && (size_t)written < capacity; ++i) {
        written += snprintf(out + written, capacity - (size_t)written, ",%s", parser.field(i));
    }
}

struct Counts {
    uint64_t sent = 0;
    uint64_t hit = 0;  // frames with at least one corrupted byte
    uint64_t intact = 0;
    uint64_t corruptedAccepted = 0;
};

Counts measure(double rate, uint64_t frames, uint64_t seed)
{
    char line[Protocol::LINE_BUFFER_SIZE];
    char sentBody[Protocol::LINE_BUFFER_SIZE];
    char receivedBody[2 * Protocol::LINE_BUFFER_SIZE];
    FrameWriter writer(line, sizeof line);
    FrameParser parser;
    line_noise_t noise;
    memset(&noise, 0, sizeof noise);
    line_noise_set(&noise, rate, splitmix64_next(&seed));
    Draws draws = {splitmix64_next(&seed)};
    Counts counts;
    for (uint64_t i = 0; i < frames; ++i) {
        const char* text = makeFrame(writer, (uint16_t)i, draws);
        if (!text) {
            fprintf(stderr, "integrity_bench: a frame failed to encode\n");
            exit(1);
        }
        const char* star = strrchr(text, '*');
        size_t bodyLength = (size_t)(star - text - 1);
        memcpy(sentBody, text + 1, bodyLength);
        sentBody[bodyLength] = '\0';
        uint64_t corruptedBefore = noise.corrupted_bytes;
        ++counts.sent;
        for (const char* c = text; *c != '\0'; ++c) {
            if (!parser.feed((char)line_noise_apply(&noise, (uint8_t)*c))) {
                continue;
            }
            rejoin(parser, receivedBody, sizeof receivedBody);
            if (strcmp(receivedBody, sentBody) == 0) {
                ++counts.intact;
            } else {
                ++counts.corruptedAccepted;
            }
        }
        if (noise.corrupted_bytes != corruptedBefore) {
            ++counts.hit;
        }
    }
    return counts;
}

}  // namespace

int main(int argc, char** argv)
{
    uint64_t frames = argc > 1 ? strtoull(argv[1], 0, 10) : kDefaultFrames;
    if (frames == 0) {
        fprintf(stderr, "usage: integrity_bench [frames per rate] [rate ...]\n");
        return 2;
    }
    printf("integrity: protocol %u line check, %llu frames per byte error rate "
           "(IMU, CHS, SETPRG, SETCOE mixed)\n",
           (unsigned)Protocol::VERSION, (unsigned long long)frames);
    int rateCount = argc > 2 ? argc - 2 : (int)(sizeof kDefaultRates / sizeof kDefaultRates[0]);
    for (int r = 0; r < rateCount; ++r) {
        double rate = argc > 2 ? strtod(argv[2 + r], 0) : kDefaultRates[r];
        Counts counts = measure(rate, frames, 0x5EED0000u + (uint64_t)r);
        double perMillion = 1e6 * (double)counts.corruptedAccepted / (double)counts.sent;
        printf("  byte error rate %.4g: %llu of %llu frames hit, %llu arrived intact, "
               "%llu corrupted frames accepted = %.2f per million frames sent",
               rate, (unsigned long long)counts.hit, (unsigned long long)counts.sent, (unsigned long long)counts.intact,
               (unsigned long long)counts.corruptedAccepted, perMillion);
        if (counts.corruptedAccepted == 0) {
            printf(" (95 %% upper bound %.2f)", 1e6 * kZeroEventsUpperBound95 / (double)counts.sent);
        }
        printf("\n");
    }
    return 0;
}
