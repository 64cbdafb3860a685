/*
 * gyrolink: the board's link in C (see gyrolink.h and docs/link.md).
 * Every read is bounds-checked; a frame that does not decode exactly (a
 * field out of range, a byte left over) is refused, never half-filled.
 */
#include "gyrolink.h"

#include <string.h>

/* CRC-16/IBM-3740 (CCITT-FALSE), bit by bit: 16 shifts a byte, cheap
 * beside a frame's 80 bytes a millisecond. */
uint16_t gl_crc16(const uint8_t *data, size_t len)
{
    uint16_t crc = 0xFFFFu;
    size_t i;
    for (i = 0; i < len; i++) {
        int b;
        crc = (uint16_t)(crc ^ (uint16_t)((uint16_t)data[i] << 8));
        for (b = 0; b < 8; b++) {
            crc = (crc & 0x8000u) ? (uint16_t)((crc << 1) ^ 0x1021u) : (uint16_t)(crc << 1);
        }
    }
    return crc;
}

/* ---- COBS ---------------------------------------------------------- */

/* Decode `len` COBS bytes (no delimiter) into out; the decoded length, or
 * (size_t)-1 where a code byte is 0 or runs past the end. */
static size_t cobs_decode(const uint8_t *in, size_t len, uint8_t *out, size_t cap)
{
    size_t i = 0, o = 0;
    while (i < len) {
        uint8_t code = in[i++];
        size_t k;
        if (code == 0 || i + (size_t)code - 1 > len) {
            return (size_t)-1;
        }
        for (k = 1; k < code; k++) {
            if (o >= cap) {
                return (size_t)-1;
            }
            out[o++] = in[i++];
        }
        /* A zero ends every run but a full one (255) and the last. */
        if (code != 0xFF && i < len) {
            if (o >= cap) {
                return (size_t)-1;
            }
            out[o++] = 0;
        }
    }
    return o;
}

/* ---- postcard reader ----------------------------------------------- */

typedef struct {
    const uint8_t *p;
    size_t n;
    size_t i;
    int bad;
} reader;

static uint8_t rd_u8(reader *r)
{
    if (r->i >= r->n) {
        r->bad = 1;
        return 0;
    }
    return r->p[r->i++];
}

/* LEB128, at most `max_bytes`, the value at most `limit`. */
static uint64_t rd_varint(reader *r, unsigned max_bytes, uint64_t limit)
{
    uint64_t v = 0;
    unsigned k;
    for (k = 0; k < max_bytes; k++) {
        uint8_t b = rd_u8(r);
        if (r->bad) {
            return 0;
        }
        v |= (uint64_t)(b & 0x7Fu) << (7u * k);
        if ((b & 0x80u) == 0) {
            if (v > limit) {
                r->bad = 1;
                return 0;
            }
            return v;
        }
    }
    r->bad = 1;
    return 0;
}

static uint16_t rd_v16(reader *r) { return (uint16_t)rd_varint(r, 3, 0xFFFFu); }
static uint32_t rd_v32(reader *r) { return (uint32_t)rd_varint(r, 5, 0xFFFFFFFFu); }
static uint64_t rd_v64(reader *r) { return rd_varint(r, 10, UINT64_MAX); }

static int32_t rd_zz32(reader *r)
{
    uint32_t u = rd_v32(r);
    return (int32_t)((u >> 1) ^ (uint32_t)(0u - (u & 1u)));
}

static int16_t rd_zz16(reader *r)
{
    uint16_t u = rd_v16(r);
    return (int16_t)((uint16_t)(u >> 1) ^ (uint16_t)(0u - (u & 1u)));
}

static uint32_t rd_le32(reader *r)
{
    uint32_t v = 0;
    int k;
    for (k = 0; k < 4; k++) {
        v |= (uint32_t)rd_u8(r) << (8 * k);
    }
    return v;
}

static uint64_t rd_le64(reader *r)
{
    uint64_t lo = rd_le32(r);
    uint64_t hi = rd_le32(r);
    return lo | (hi << 32);
}

static float rd_f32(reader *r)
{
    uint32_t bits = rd_le32(r);
    float f;
    memcpy(&f, &bits, sizeof f);
    return f;
}

/* Option's tag: 0 or 1. */
static uint8_t rd_option(reader *r)
{
    uint8_t t = rd_u8(r);
    if (t > 1) {
        r->bad = 1;
    }
    return t;
}

/* A Vec's length, at most GL_MAX_GYROS. */
static uint8_t rd_len(reader *r)
{
    return (uint8_t)rd_varint(r, 1, GL_MAX_GYROS);
}

/* An enum's variant index, below `count`. */
static uint8_t rd_variant(reader *r, uint8_t count)
{
    uint32_t v = rd_v32(r);
    if (v >= count) {
        r->bad = 1;
        return 0;
    }
    return (uint8_t)v;
}

/* ---- bodies -------------------------------------------------------- */

static void rd_sample(reader *r, gl_sample *s)
{
    int a;
    uint8_t i;
    s->seq = rd_le32(r);
    s->t_us = rd_le64(r);
    for (a = 0; a < 3; a++) {
        s->age_us[a] = rd_v16(r);
    }
    s->has_predicted = rd_option(r);
    s->predicted_us = s->has_predicted ? rd_v16(r) : 0;
    for (a = 0; a < 3; a++) {
        s->rate_dps[a] = rd_f32(r);
    }
    s->valid = rd_u8(r);
    s->degraded = rd_u8(r);
    for (a = 0; a < 3; a++) {
        s->used[a] = rd_u8(r);
    }
    s->n_health = rd_len(r);
    for (i = 0; i < s->n_health && !r->bad; i++) {
        s->health[i] = rd_u8(r);
    }
    s->has_noise = rd_option(r);
    if (s->has_noise) {
        s->noise.axis = rd_u8(r);
        s->noise.seq = rd_le32(r);
        s->noise.len = rd_v16(r);
        s->noise.bridged = rd_u8(r);
        for (a = 0; a < 3; a++) {
            s->noise.sigma_dps[a] = rd_f32(r);
        }
    }
    s->has_angle = rd_option(r);
    for (a = 0; a < 3; a++) {
        s->angle_turn32[a] = s->has_angle ? rd_le32(r) : 0;
    }
}

static void rd_raw(reader *r, gl_raw *s)
{
    uint8_t i;
    int a;
    s->seq = rd_le32(r);
    s->t_us = rd_le64(r);
    s->n_age = rd_len(r);
    for (i = 0; i < s->n_age && !r->bad; i++) {
        s->age_us[i] = rd_v16(r);
    }
    s->n_rates = rd_len(r);
    for (i = 0; i < s->n_rates && !r->bad; i++) {
        for (a = 0; a < 3; a++) {
            s->rate_dps[i][a] = rd_f32(r);
        }
    }
    s->n_health = rd_len(r);
    for (i = 0; i < s->n_health && !r->bad; i++) {
        s->health[i] = rd_u8(r);
    }
}

static void rd_settings(reader *r, gl_settings *s)
{
    s->mode = rd_variant(r, 2);
    s->method = rd_variant(r, 3);
    s->divider = rd_v16(r);
    s->status_every = rd_v32(r);
    s->compensation = rd_variant(r, 3);
    s->horizon_us = s->compensation == 2 ? rd_v16(r) : 0;
    s->angle = rd_option(r); /* a bool: 0 or 1, as an Option's tag */
    s->path_trim_us = rd_zz16(r);
}

static void rd_status(reader *r, gl_status *s)
{
    uint8_t i;
    int a;
    s->seq = rd_v32(r);
    s->t_us = rd_v64(r);
    rd_settings(r, &s->settings);
    for (a = 0; a < 3; a++) {
        s->noise_tau[a] = rd_v16(r);
    }
    s->sample_us = rd_v32(r);
    s->overruns = rd_v32(r);
    s->sent = rd_v32(r);
    s->dropped = rd_v32(r);
    s->accepted = rd_v32(r);
    s->rejected = rd_v32(r);
    s->stack_peak = rd_v32(r);
    s->store = rd_variant(r, 4);
    s->n_gyros = rd_len(r);
    for (i = 0; i < s->n_gyros && !r->bad; i++) {
        gl_gyro_status *g = &s->gyros[i];
        g->flags = rd_u8(r);
        g->reads = rd_v32(r);
        g->errors = rd_v32(r);
        g->excluded = rd_v32(r);
        g->restarts = rd_v32(r);
        g->restarted = rd_v32(r);
        for (a = 0; a < 3; a++) {
            g->scale_ppm[a] = rd_zz32(r);
        }
        for (a = 0; a < 3; a++) {
            g->bias_mdps[a] = rd_zz16(r);
        }
        g->clock = rd_variant(r, 3);
        g->clock_ppm = rd_zz32(r);
        g->late = rd_v32(r);
        g->overflows = rd_v32(r);
        g->bad = rd_v32(r);
        g->cuts = rd_v32(r);
        g->resent = rd_v32(r);
    }
}

static void rd_ack(reader *r, gl_ack *s)
{
    s->has_id = rd_option(r);
    s->id = s->has_id ? rd_u8(r) : 0;
    /* Result<(), Reject>: 0 Ok, 1 then the reason. */
    s->ok = (uint8_t)(rd_option(r) == 0);
    s->reject = s->ok ? 0 : rd_variant(r, 7);
}

static void rd_sync(reader *r, gl_sync *s)
{
    s->state = rd_variant(r, 4);
    s->board_us = rd_le64(r);
    s->ctrl_us = rd_le64(r);
    s->ppm = rd_f32(r);
    s->residual_us = rd_f32(r);
    s->dropped = rd_v32(r);
    s->unpaired = rd_v32(r);
}

static void rd_info(reader *r, gl_info *s)
{
    uint8_t i;
    int k;
    for (k = 0; k < 12; k++) {
        s->uid[k] = rd_u8(r);
    }
    for (k = 0; k < 3; k++) {
        s->firmware[k] = rd_u8(r);
    }
    s->build = rd_le32(r);
    s->n_chips = rd_len(r);
    for (i = 0; i < s->n_chips && !r->bad; i++) {
        gl_chip_info *c = &s->chips[i];
        c->part = rd_variant(r, 3);
        c->id = rd_v16(r);
        c->start = rd_variant(r, 4);
        c->has_temp = rd_option(r);
        c->temp_cc = c->has_temp ? rd_zz16(r) : 0;
    }
}

int gl_sync_to_controller(const gl_sync *s, uint64_t board_us, uint64_t *out)
{
    double dt, c;
    if (s->state != 2) {
        return 0;
    }
    /* Differences of a few seconds: exact in a double. */
    dt = board_us >= s->board_us ? (double)(board_us - s->board_us) : -(double)(s->board_us - board_us);
    c = dt * (1.0 + (double)s->ppm * 1e-6);
    *out = c >= 0 ? s->ctrl_us + (uint64_t)(c + 0.5) : s->ctrl_us - (uint64_t)(-c + 0.5);
    return 1;
}

/* ---- frames -------------------------------------------------------- */

gl_error gl_decode_frame(const uint8_t *frame, size_t len, gl_frame *out)
{
    uint8_t payload[GL_MAX_PAYLOAD + 2];
    size_t n;
    reader r;
    uint16_t crc;
    if (len > GL_MAX_FRAME) {
        return GL_ERR_TOO_LONG;
    }
    n = cobs_decode(frame, len, payload, sizeof payload);
    if (n == (size_t)-1) {
        return GL_ERR_COBS;
    }
    if (n < 1 + 4 + 1 + 2) {
        return GL_ERR_SHORT;
    }
    crc = (uint16_t)(payload[n - 2] | (payload[n - 1] << 8));
    if (gl_crc16(payload, n - 2) != crc) {
        return GL_ERR_CRC;
    }
    if (payload[0] != GL_VERSION) {
        return GL_ERR_VERSION;
    }
    memset(out, 0, sizeof *out);
    r.p = payload;
    r.n = n - 2;
    r.i = 1;
    r.bad = 0;
    out->link_seq = rd_le32(&r);
    out->kind = (gl_kind)rd_variant(&r, 6);
    switch (out->kind) {
    case GL_SAMPLE:
        rd_sample(&r, &out->u.sample);
        break;
    case GL_RAW:
        rd_raw(&r, &out->u.raw);
        break;
    case GL_STATUS:
        rd_status(&r, &out->u.status);
        break;
    case GL_ACK:
        rd_ack(&r, &out->u.ack);
        break;
    case GL_SYNC:
        rd_sync(&r, &out->u.sync);
        break;
    case GL_INFO:
        rd_info(&r, &out->u.info);
        break;
    }
    if (r.bad || r.i != r.n) {
        memset(out, 0, sizeof *out);
        return GL_ERR_MALFORMED;
    }
    return GL_OK;
}

void gl_decoder_init(gl_decoder *d)
{
    memset(d, 0, sizeof *d);
}

static void count(gl_stats *s, gl_error e, size_t bytes)
{
    switch (e) {
    case GL_ERR_COBS: s->cobs++; break;
    case GL_ERR_CRC: s->crc++; break;
    case GL_ERR_TOO_LONG: s->too_long++; break;
    case GL_ERR_VERSION: s->version++; break;
    case GL_ERR_MALFORMED: s->malformed++; break;
    case GL_ERR_SHORT: s->short_++; break;
    case GL_OK:
    case GL_ERR_ARGUMENT:
        return;
    }
    s->bytes_dropped += (uint32_t)bytes;
}

int gl_feed(gl_decoder *d, uint8_t byte, gl_frame *out)
{
    gl_error e;
    size_t n;
    if (byte != 0) {
        if (d->len < sizeof d->buf) {
            d->buf[d->len++] = byte;
        } else {
            if (!d->overflow) {
                d->overflow = 1;
            }
            d->stats.bytes_dropped++;
        }
        return -1;
    }
    /* A delimiter: the frame before it, if any. */
    n = d->len;
    d->len = 0;
    if (d->overflow) {
        d->overflow = 0;
        count(&d->stats, GL_ERR_TOO_LONG, n);
        return GL_ERR_TOO_LONG;
    }
    if (n == 0) {
        return -1; /* back-to-back delimiters: nothing between */
    }
    e = gl_decode_frame(d->buf, n, out);
    count(&d->stats, e, n);
    return (int)e;
}

/* ---- commands ------------------------------------------------------ */

typedef struct {
    uint8_t *p;
    size_t cap;
    size_t n;
    int bad;
} writer;

static void wr_u8(writer *w, uint8_t b)
{
    if (w->n >= w->cap) {
        w->bad = 1;
        return;
    }
    w->p[w->n++] = b;
}

static void wr_varint(writer *w, uint32_t v)
{
    while (v >= 0x80u) {
        wr_u8(w, (uint8_t)(v | 0x80u));
        v >>= 7;
    }
    wr_u8(w, (uint8_t)v);
}

size_t gl_encode_command(const gl_command *c, uint32_t link_seq, uint8_t *out, size_t cap)
{
    uint8_t payload[32];
    writer w;
    uint16_t crc;
    size_t i, code_at, o;
    int k;
    w.p = payload;
    w.cap = sizeof payload;
    w.n = 0;
    w.bad = 0;
    wr_u8(&w, (uint8_t)GL_VERSION);
    for (k = 0; k < 4; k++) {
        wr_u8(&w, (uint8_t)(link_seq >> (8 * k)));
    }
    wr_u8(&w, c->id);
    wr_varint(&w, (uint32_t)c->op);
    switch (c->op) {
    case GL_SET_MODE:
        if (c->arg > 1) return 0;
        wr_varint(&w, c->arg);
        break;
    case GL_SET_METHOD:
        if (c->arg > 2) return 0;
        wr_varint(&w, c->arg);
        break;
    case GL_SET_DIVIDER:
        if (c->arg > 0xFFFFu) return 0;
        wr_varint(&w, c->arg);
        break;
    case GL_SET_STATUS_EVERY:
        wr_varint(&w, c->arg);
        break;
    case GL_REQUEST_STATUS:
    case GL_REQUEST_INFO:
    case GL_SAVE_SETTINGS:
    case GL_FACTORY_RESET:
        break;
    case GL_SYNC_TIME: {
        uint64_t v = c->time_us;
        while (v >= 0x80u) {
            wr_u8(&w, (uint8_t)(v | 0x80u));
            v >>= 7;
        }
        wr_u8(&w, (uint8_t)v);
        break;
    }
    case GL_SET_ANGLE:
        if (c->arg > 1) return 0;
        wr_u8(&w, (uint8_t)c->arg);
        break;
    case GL_SET_COMPENSATION:
        if (c->arg > 2) return 0;
        wr_varint(&w, c->arg);
        if (c->arg == 2) {
            wr_varint(&w, c->horizon_us);
        }
        break;
    case GL_SET_PATH_TRIM: {
        /* An i16 as postcard writes it: zigzag, then a varint. */
        int32_t v = c->path_trim_us;
        wr_varint(&w, (uint32_t)((v < 0) ? ((uint32_t)(-(v + 1)) << 1) | 1u : (uint32_t)v << 1));
        break;
    }
    default:
        return 0;
    }
    crc = gl_crc16(payload, w.n);
    wr_u8(&w, (uint8_t)(crc & 0xFFu));
    wr_u8(&w, (uint8_t)(crc >> 8));
    if (w.bad) {
        return 0;
    }
    /* COBS: each run of non-zero bytes behind a code byte (its length +
     * 1), the zero that ends it dropped; then the delimiter. The payload
     * is under 254 bytes, so no full run. */
    if (cap < w.n + 2) {
        return 0;
    }
    o = 0;
    code_at = o++;
    out[code_at] = 1;
    for (i = 0; i < w.n; i++) {
        if (payload[i] == 0) {
            code_at = o++;
            out[code_at] = 1;
        } else {
            out[o++] = payload[i];
            out[code_at]++;
        }
    }
    out[o++] = 0;
    return o;
}
