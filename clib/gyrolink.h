/*
 * gyrolink: the gyro board's output link for the antenna controller, in C.
 *
 * Decodes every frame the board sends and encodes every command it takes,
 * as docs/link.md specifies them (protocol version 7): COBS framing with a
 * 0x00 delimiter, CRC-16/IBM-3740 (poly 0x1021, init 0xFFFF) over the
 * payload, payload = version (u8) | link_seq (u32 LE) | body (postcard).
 *
 * C99, no allocation, no dependency beyond <stdint.h>, <stddef.h> and
 * <string.h>; compiles as C++ too. The decoder is a byte-at-a-time state
 * machine: feed it the bytes as the UART delivers them, in any chunking,
 * and it hands back each complete frame or says why it refused one.
 */
#ifndef GYROLINK_H
#define GYROLINK_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/** The protocol version this library speaks. */
#define GL_VERSION 8u
/** Gyros a frame can describe at most. */
#define GL_MAX_GYROS 8u
/** Longest payload (version, link_seq, body), bytes. */
#define GL_MAX_PAYLOAD 768u
/** Longest encoded frame: the payload, its CRC, COBS's code bytes and the
 * delimiter. */
#define GL_MAX_FRAME (GL_MAX_PAYLOAD + 2u + (GL_MAX_PAYLOAD + 2u) / 254u + 2u)

/** Why a frame was refused, or a call failed. */
typedef enum {
    GL_OK = 0,
    /** A COBS code byte points past the frame's end. */
    GL_ERR_COBS = 1,
    /** The CRC does not match: the frame was damaged. */
    GL_ERR_CRC = 2,
    /** Longer than GL_MAX_FRAME before its delimiter. */
    GL_ERR_TOO_LONG = 3,
    /** Another protocol version. */
    GL_ERR_VERSION = 4,
    /** The body does not decode as a frame, or bytes are left over. */
    GL_ERR_MALFORMED = 5,
    /** Shorter than a version, a link sequence number and a CRC. */
    GL_ERR_SHORT = 6,
    /** (Encoding) the output buffer is too small, or an argument out of
     * range. */
    GL_ERR_ARGUMENT = 7
} gl_error;

/** What a frame carries. */
typedef enum {
    GL_SAMPLE = 0,
    GL_RAW = 1,
    GL_STATUS = 2,
    GL_ACK = 3,
    GL_SYNC = 4,
    GL_INFO = 5
} gl_kind;

/** An E-DAVAR noise estimate of one fused axis. */
typedef struct {
    uint8_t axis;
    /** The sample the estimate describes. */
    uint32_t seq;
    /** Window length, samples. */
    uint16_t len;
    /** Missing samples of the window, bridged. */
    uint8_t bridged;
    /** Allan deviation at the status frame's noise_tau, deg/s. */
    float sigma_dps[3];
} gl_noise;

/** A fused sample (frame kind 0). */
typedef struct {
    uint32_t seq;
    /** When the sample was read and queued, us of the board's clock. */
    uint64_t t_us;
    /** The rate describes t_us - age_us[a]. */
    uint16_t age_us[3];
    /** 1: rate_dps is predicted to t_us + predicted_us. */
    uint8_t has_predicted;
    uint16_t predicted_us;
    /** NaN where the axis is not valid. */
    float rate_dps[3];
    uint8_t valid;
    uint8_t degraded;
    uint8_t used[3];
    uint8_t n_health;
    uint8_t health[GL_MAX_GYROS];
    uint8_t has_noise;
    gl_noise noise;
    /** 1 with the angle setting on: angle_turn32[a], axis a's fused rate
     * integrated since the angle was turned on, 2^-32 turn, wrapping; the angle between two
     * frames is (int32_t)(new - old) * 360.0 / 4294967296.0 deg. */
    uint8_t has_angle;
    uint32_t angle_turn32[3];
} gl_sample;

/** Every gyro's own reading (frame kind 1, raw mode). */
typedef struct {
    uint32_t seq;
    uint64_t t_us;
    uint8_t n_age;
    uint16_t age_us[GL_MAX_GYROS];
    uint8_t n_rates;
    float rate_dps[GL_MAX_GYROS][3];
    uint8_t n_health;
    uint8_t health[GL_MAX_GYROS];
} gl_raw;

/** The board's settings. mode: 0 Fused, 1 Raw; method: 0 Mean, 1 Zhang,
 * 2 Adaptive; compensation: 0 Off, 1 ToFrame, 2 Horizon(horizon_us);
 * angle: 1 when sample frames carry the integrated angle; path_trim_us:
 * how much longer the ICM-42688-P's signal path was measured than its
 * datasheet's reading, µs (new in version 8). */
typedef struct {
    uint8_t mode;
    uint8_t method;
    uint16_t divider;
    uint32_t status_every;
    uint8_t compensation;
    uint16_t horizon_us;
    uint8_t angle;
    int16_t path_trim_us;
} gl_settings;

/** One gyro in a status frame. clock: 0 Polled, 1 Own, 2 ClkIn. */
typedef struct {
    uint8_t flags;
    uint32_t reads, errors, excluded, restarts, restarted;
    int32_t scale_ppm[3];
    int16_t bias_mdps[3];
    uint8_t clock;
    int32_t clock_ppm;
    uint32_t late;
    uint32_t overflows, bad, cuts, resent;
} gl_gyro_status;

/** Counters and settings (frame kind 2). */
typedef struct {
    uint32_t seq;
    uint64_t t_us;
    gl_settings settings;
    uint16_t noise_tau[3];
    uint32_t sample_us;
    uint32_t overruns;
    uint32_t sent, dropped, accepted, rejected;
    uint32_t stack_peak;
    /** The settings store: 0 Absent (no store on this build), 1 Defaults
     * (nothing saved), 2 Stored (a record read back and checked), 3 Corrupt
     * (the record at boot did not check: defaults until the next save). */
    uint8_t store;
    uint8_t n_gyros;
    gl_gyro_status gyros[GL_MAX_GYROS];
} gl_status;

/** The answer to a command (frame kind 3). reject (when ok is 0):
 * 0 Corrupt, 1 TooLong, 2 Version, 3 Malformed, 4 OutOfRange, 5 Refused,
 * 6 Storage (the flash failed, or did not read back what it wrote). */
typedef struct {
    uint8_t has_id;
    uint8_t id;
    uint8_t ok;
    uint8_t reject;
} gl_ack;

/** The controller's clock as the board tracks it (frame kind 4), after
 * each GL_SYNC_TIME and when the pulse is lost. state: 0 Off, 1 Acquiring,
 * 2 Locked, 3 Lost. While Locked, board instant t (us) is, in the
 * controller's clock, ctrl_us + (t - board_us) * (1 + ppm * 1e-6):
 * gl_sync_to_controller. */
typedef struct {
    uint8_t state;
    uint64_t board_us;
    uint64_t ctrl_us;
    float ppm;
    float residual_us;
    uint32_t dropped, unpaired;
} gl_sync;

/** One gyro in an info frame. part: 0 Unknown, 1 ICM-42688-P, 2 ADXRS453;
 * id: its identity register as read at start-up (0x47; 0x52xx); start:
 * 0 Unknown, 1 Passed, 2 InitFailed, 3 SelfTestFailed; temp_cc: die
 * temperature, 0.01 deg C, when has_temp. */
typedef struct {
    uint8_t part;
    uint16_t id;
    uint8_t start;
    uint8_t has_temp;
    int16_t temp_cc;
} gl_chip_info;

/** The board and its chips (frame kind 5): on request (GL_REQUEST_INFO) and
 * once every status period, half way between status frames. */
typedef struct {
    uint8_t uid[12];
    uint8_t firmware[3];
    /** The commit's first 32 bits (0: unknown). */
    uint32_t build;
    uint8_t n_chips;
    gl_chip_info chips[GL_MAX_GYROS];
} gl_info;

/** One decoded frame. */
typedef struct {
    uint32_t link_seq;
    gl_kind kind;
    union {
        gl_sample sample;
        gl_raw raw;
        gl_status status;
        gl_ack ack;
        gl_sync sync;
        gl_info info;
    } u;
} gl_frame;

/** Frames refused so far, by reason, and the bytes they held. */
typedef struct {
    uint32_t cobs, crc, too_long, version, malformed, short_;
    uint32_t bytes_dropped;
} gl_stats;

/** The streaming decoder. Zero it (or gl_decoder_init) before use. */
typedef struct {
    uint8_t buf[GL_MAX_FRAME];
    size_t len;
    /** Skipping to the next delimiter after an over-long frame. */
    uint8_t overflow;
    gl_stats stats;
} gl_decoder;

/** Start a decoder with no bytes and no counts. */
void gl_decoder_init(gl_decoder *d);

/**
 * Feed one byte. Returns GL_OK with *out filled when the byte completed a
 * frame; a gl_error when it completed a frame that was refused (counted in
 * d->stats); and -1 when no frame ended with it.
 */
int gl_feed(gl_decoder *d, uint8_t byte, gl_frame *out);

/** Decode one whole frame's bytes (without its 0x00 delimiter). */
gl_error gl_decode_frame(const uint8_t *frame, size_t len, gl_frame *out);

/** CRC-16/IBM-3740 of `len` bytes ("123456789" gives 0x29B1). */
uint16_t gl_crc16(const uint8_t *data, size_t len);

/** The commands' operations. */
typedef enum {
    GL_SET_MODE = 0,
    GL_SET_METHOD = 1,
    GL_SET_DIVIDER = 2,
    GL_SET_STATUS_EVERY = 3,
    GL_REQUEST_STATUS = 4,
    GL_SET_COMPENSATION = 5,
    /** Save the settings in force to flash (acknowledged once read back). */
    GL_SAVE_SETTINGS = 6,
    /** The default settings now, the saved ones erased. */
    GL_FACTORY_RESET = 7,
    /** arg 1: sample frames carry the integrated angle; 0: they do not. */
    GL_SET_ANGLE = 8,
    /** time_us: the controller's time at its last sync pulse. */
    GL_SYNC_TIME = 9,
    /** Send an info frame now. */
    GL_REQUEST_INFO = 10,
    /** path_trim_us: the signal path's trim, ±800 µs (new in version 8). */
    GL_SET_PATH_TRIM = 11
} gl_op;

/** A command: `arg` is the mode, the method, the divider, the status
 * period, the angle (0 or 1), or the compensation (0 Off, 1 ToFrame, 2 Horizon with
 * `horizon_us`); unused for GL_REQUEST_STATUS, GL_SAVE_SETTINGS,
 * GL_FACTORY_RESET and GL_REQUEST_INFO; GL_SYNC_TIME takes `time_us`,
 * GL_SET_PATH_TRIM `path_trim_us`. */
typedef struct {
    uint8_t id;
    gl_op op;
    uint32_t arg;
    uint16_t horizon_us;
    uint64_t time_us;
    int16_t path_trim_us;
} gl_command;

/**
 * Encode a command frame, delimiter included, into out[0..cap). Returns
 * the bytes written, or 0 (GL_ERR_ARGUMENT) when it does not fit or an
 * argument is not one the protocol has. `link_seq` counts the host's own
 * frames from 0.
 */
size_t gl_encode_command(const gl_command *c, uint32_t link_seq, uint8_t *out, size_t cap);

/**
 * A board instant (us of its clock: a sample's t_us - age_us[a], say) in
 * the controller's clock by the newest sync frame: 1 with *out set while
 * it is Locked, 0 otherwise (the instant is then on the board's clock
 * only).
 */
int gl_sync_to_controller(const gl_sync *s, uint64_t board_us, uint64_t *out);

#ifdef __cplusplus
}
#endif

#endif /* GYROLINK_H */
