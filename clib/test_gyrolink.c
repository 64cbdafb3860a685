/*
 * gyrolink's tests: the specification's byte examples (docs/link.md),
 * damage and resynchronisation, a stream of random bytes; and, given a
 * recording of the board's link, its frames counted by kind and the CRC-32
 * of every sample frame's rates, for `cargo xtask clib` to hold against
 * the Rust decoder's (`gyro check`).
 *
 *   test_gyrolink            the tests
 *   test_gyrolink FILE       decode a recording
 */
#include "gyrolink.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int failures = 0;

#define CHECK(cond)                                                              \
    do {                                                                         \
        if (!(cond)) {                                                           \
            fprintf(stderr, "%s:%d: FAILED: %s\n", __FILE__, __LINE__, #cond);    \
            failures++;                                                          \
        }                                                                        \
    } while (0)

/* Feed `len` bytes; the last frame decoded into *last; the count of
 * frames decoded and refused. */
static void feed_all(gl_decoder *d, const uint8_t *b, size_t len, gl_frame *last, int *ok, int *bad)
{
    size_t i;
    gl_frame f;
    for (i = 0; i < len; i++) {
        int r = gl_feed(d, b[i], &f);
        if (r == GL_OK) {
            *last = f;
            (*ok)++;
        } else if (r > 0) {
            (*bad)++;
        }
    }
}

/* Whether command `op` (id 7, link_seq 0, argument `arg` or `time_us`)
 * encodes to exactly want[0..len); len 0: whether it encodes at all. */
static int encodes_as(gl_op op, uint32_t arg, uint64_t time_us, const uint8_t *want, size_t len)
{
    uint8_t out[64];
    gl_command c;
    size_t n;
    memset(&c, 0, sizeof c);
    c.id = 7;
    c.op = op;
    c.arg = arg;
    c.time_us = time_us;
    n = gl_encode_command(&c, 0, out, sizeof out);
    return len == 0 ? n != 0 : n == len && memcmp(out, want, n) == 0;
}

static void tests(void)
{
    /* CRC-16/IBM-3740's check value. */
    CHECK(gl_crc16((const uint8_t *)"123456789", 9) == 0x29B1);

    /* RequestStatus with id 7, the host's first frame. */
    {
        static const uint8_t want[] = {0x02, 0x08, 0x01, 0x01, 0x01, 0x05, 0x07, 0x04, 0x70, 0xbb, 0x00};
        uint8_t out[64];
        gl_command c;
        CHECK(encodes_as(GL_REQUEST_STATUS, 0, 0, want, sizeof want));
        /* Too small a buffer, an argument the protocol does not have. */
        memset(&c, 0, sizeof c);
        c.id = 7;
        c.op = GL_REQUEST_STATUS;
        CHECK(gl_encode_command(&c, 0, out, 5) == 0);
        CHECK(!encodes_as(GL_SET_METHOD, 3, 0, NULL, 0));
    }

    /* The other commands with id 7, link_seq 0: the same bytes the Rust
     * encoder gives (link::tests). */
    {
        static const uint8_t save[] = {0x02, 0x08, 0x01, 0x01, 0x01, 0x05, 0x07, 0x06, 0x32, 0x9b, 0x00};
        static const uint8_t reset[] = {0x02, 0x08, 0x01, 0x01, 0x01, 0x05, 0x07, 0x07, 0x13, 0x8b, 0x00};
        /* SyncTime(0x123456789ABC): a u64 varint. */
        static const uint8_t sync[] = {0x02, 0x08, 0x01, 0x01, 0x01, 0x0c, 0x07, 0x09, 0xbc, 0xb5, 0xe2,
                                       0xb3, 0xc5, 0xc6, 0x04, 0xe2, 0x96, 0x00};
        /* SetPathTrim(+354): an i16 as a zigzag varint, 708 = c4 05. */
        static const uint8_t trim[] = {0x02, 0x08, 0x01, 0x01, 0x01, 0x07, 0x07, 0x0b, 0xc4, 0x05, 0x64, 0x1a, 0x00};
        uint8_t out[64];
        gl_command c;
        static const uint8_t info[] = {0x02, 0x08, 0x01, 0x01, 0x01, 0x05, 0x07, 0x0a, 0xbe, 0x5a, 0x00};
        /* SetAngle(true): a bool is 0 or 1. */
        static const uint8_t angle[] = {0x02, 0x08, 0x01, 0x01, 0x01, 0x06, 0x07, 0x08, 0x01, 0xfc, 0x33, 0x00};
        CHECK(encodes_as(GL_SAVE_SETTINGS, 0, 0, save, sizeof save));
        CHECK(encodes_as(GL_FACTORY_RESET, 0, 0, reset, sizeof reset));
        CHECK(encodes_as(GL_SYNC_TIME, 0, 0x123456789ABCull, sync, sizeof sync));
        CHECK(encodes_as(GL_REQUEST_INFO, 0, 0, info, sizeof info));
        CHECK(encodes_as(GL_SET_ANGLE, 1, 0, angle, sizeof angle));
        CHECK(!encodes_as(GL_SET_ANGLE, 2, 0, NULL, 0));
        memset(&c, 0, sizeof c);
        c.id = 7;
        c.op = GL_SET_PATH_TRIM;
        c.path_trim_us = 354;
        CHECK(gl_encode_command(&c, 0, out, sizeof out) == sizeof trim && memcmp(out, trim, sizeof trim) == 0);
    }
    /* A board instant 1 s after the sync line's anchor, 50 ppm fast. */
    {
        gl_sync s;
        uint64_t t = 0;
        memset(&s, 0, sizeof s);
        s.state = 2;
        s.board_us = 5000000u;
        s.ctrl_us = 9000000000ull;
        s.ppm = 50.0f;
        CHECK(gl_sync_to_controller(&s, 6000000u, &t) == 1 && t == 9001000050ull);
        CHECK(gl_sync_to_controller(&s, 4000000u, &t) == 1 && t == 8998999950ull);
        s.state = 3;
        CHECK(gl_sync_to_controller(&s, 6000000u, &t) == 0);
    }

    /* The board's sixth frame, rejecting command 7 as out of range. */
    {
        static const uint8_t wire[] = {0x03, 0x08, 0x05, 0x01, 0x01, 0x08, 0x03, 0x01, 0x07, 0x01, 0x04, 0xfd, 0xb2, 0x00};
        gl_decoder d;
        gl_frame f;
        int ok = 0, bad = 0;
        gl_decoder_init(&d);
        memset(&f, 0, sizeof f);
        feed_all(&d, wire, sizeof wire, &f, &ok, &bad);
        CHECK(ok == 1 && bad == 0);
        CHECK(f.link_seq == 5 && f.kind == GL_ACK);
        CHECK(f.u.ack.has_id == 1 && f.u.ack.id == 7 && f.u.ack.ok == 0 && f.u.ack.reject == 4);

        /* Every single-bit flip of it is refused, never misread. */
        {
            size_t i;
            int b, misread = 0;
            for (i = 0; i + 1 < sizeof wire; i++) {
                for (b = 0; b < 8; b++) {
                    uint8_t w[sizeof wire];
                    gl_frame g;
                    memcpy(w, wire, sizeof w);
                    w[i] ^= (uint8_t)(1u << b);
                    if (w[i] == 0) {
                        continue; /* a new delimiter: two pieces, each refused */
                    }
                    if (gl_decode_frame(w, sizeof w - 1, &g) == GL_OK) {
                        misread++;
                    }
                }
            }
            CHECK(misread == 0);
        }

        /* Garbage before it and a frame cut short: the decoder
         * resynchronises at the next delimiter. */
        {
            uint8_t s[64];
            size_t n = 0;
            s[n++] = 0x11;
            s[n++] = 0x22;
            s[n++] = 0x00;
            memcpy(s + n, wire, 6);
            n += 6;
            s[n++] = 0x00;
            memcpy(s + n, wire, sizeof wire);
            n += sizeof wire;
            gl_decoder_init(&d);
            ok = bad = 0;
            feed_all(&d, s, n, &f, &ok, &bad);
            CHECK(ok == 1 && bad == 2);
            CHECK(d.stats.cobs + d.stats.crc + d.stats.short_ == 2);
        }
    }

    /* A frame longer than any the board sends is refused whole. */
    {
        gl_decoder d;
        gl_frame f;
        size_t i;
        int r = -1;
        gl_decoder_init(&d);
        for (i = 0; i < GL_MAX_FRAME + 10; i++) {
            (void)gl_feed(&d, 0x01, &f);
        }
        r = gl_feed(&d, 0x00, &f);
        CHECK(r == GL_ERR_TOO_LONG && d.stats.too_long == 1);
    }

    /* A million random bytes: no crash (the sanitizers watch), and what
     * decodes is rare. */
    {
        gl_decoder d;
        gl_frame f;
        uint32_t x = 12345u;
        long i;
        int ok = 0;
        gl_decoder_init(&d);
        for (i = 0; i < 1000000L; i++) {
            x = x * 1664525u + 1013904223u;
            if (gl_feed(&d, (uint8_t)(x >> 24), &f) == GL_OK) {
                ok++;
            }
        }
        CHECK(ok < 5);
    }
}

/* CRC-32/ISO-HDLC, as the demo's digest of its fused rates. */
static uint32_t crc32_update(uint32_t c, const uint8_t *p, size_t n)
{
    size_t i;
    int b;
    for (i = 0; i < n; i++) {
        c ^= p[i];
        for (b = 0; b < 8; b++) {
            c = (c & 1u) ? (c >> 1) ^ 0xEDB88320u : c >> 1;
        }
    }
    return c;
}

static int recording(const char *path)
{
    FILE *fp = fopen(path, "rb");
    gl_decoder d;
    gl_frame f;
    long kinds[6] = {0, 0, 0, 0, 0, 0};
    long decoded = 0;
    uint32_t crc = 0xFFFFFFFFu;
    int c;
    if (!fp) {
        perror(path);
        return 2;
    }
    gl_decoder_init(&d);
    while ((c = fgetc(fp)) != EOF) {
        if (gl_feed(&d, (uint8_t)c, &f) == GL_OK) {
            decoded++;
            kinds[f.kind]++;
            if (f.kind == GL_SAMPLE) {
                int a;
                for (a = 0; a < 3; a++) {
                    uint32_t bits;
                    uint8_t le[4];
                    memcpy(&bits, &f.u.sample.rate_dps[a], 4);
                    le[0] = (uint8_t)bits;
                    le[1] = (uint8_t)(bits >> 8);
                    le[2] = (uint8_t)(bits >> 16);
                    le[3] = (uint8_t)(bits >> 24);
                    crc = crc32_update(crc, le, 4);
                }
            }
        }
    }
    fclose(fp);
    printf("frames: %ld decoded (%ld sample, %ld raw, %ld status, %ld ack, %ld sync, %ld info)\n", decoded,
           kinds[0], kinds[1], kinds[2], kinds[3], kinds[4], kinds[5]);
    printf("fused-rate CRC-32: 0x%08x\n", (unsigned)(crc ^ 0xFFFFFFFFu));
    printf("refused: cobs %u, crc %u, too long %u, version %u, malformed %u, short %u; bytes dropped %u\n",
           (unsigned)d.stats.cobs, (unsigned)d.stats.crc, (unsigned)d.stats.too_long, (unsigned)d.stats.version,
           (unsigned)d.stats.malformed, (unsigned)d.stats.short_, (unsigned)d.stats.bytes_dropped);
    return 0;
}

int main(int argc, char **argv)
{
    if (argc > 1) {
        return recording(argv[1]);
    }
    tests();
    if (failures) {
        fprintf(stderr, "%d check(s) failed\n", failures);
        return 1;
    }
    printf("gyrolink: all tests pass\n");
    return 0;
}
