/*
 * A controller's first program on the board's link: read the bytes as
 * they come (a file, or standard input: the UART), decode each frame, and
 * print the sample frames as CSV, the same columns and the same text as
 * `gyro decode` prints, so the two can be compared line by line.
 *
 *   example_decode [FILE]
 */
#include "gyrolink.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* An f32 as Rust's Display prints it: the shortest decimal that reads back
 * to the same float, in plain notation (no exponent). */
static void print_f32(float f)
{
    char e[64], digits[32];
    int p, exp10, nd = 0, i;
    const char *m;
    if (f != f) {
        fputs("NaN", stdout);
        return;
    }
    if (isinf(f)) {
        fputs(f < 0 ? "-inf" : "inf", stdout);
        return;
    }
    for (p = 1; p <= 9; p++) {
        snprintf(e, sizeof e, "%.*e", p - 1, (double)f);
        if (strtof(e, NULL) == f) {
            break;
        }
    }
    /* A float exactly halfway between two p-digit decimals: printf rounds
     * it to even, Rust's shortest form away from zero (29.1953125 reads
     * 29.195313 there). Then the p + 1 digits are exact and end in 5. */
    {
        char x[64];
        size_t k, q;
        int carried = 0;
        snprintf(x, sizeof x, "%.*e", p, (double)f);
        k = strcspn(x, "e");
        if (k > 1 && x[k - 1] == '5' && strtod(x, NULL) == (double)f) {
            /* The p digits rounded up: drop the 5, carry a 1 leftwards. */
            memmove(x + k - 1, x + k, strlen(x + k) + 1);
            for (q = k - 1; q > 0; q--) {
                char *ch = &x[q - 1];
                if (*ch == '.') {
                    continue;
                }
                if (*ch < '0' || *ch > '9') {
                    break;
                }
                if (*ch == '9') {
                    *ch = '0';
                    continue;
                }
                (*ch)++;
                carried = 1;
                break;
            }
            /* (A carry out of the first digit, 9.5 to 10, keeps printf's.) */
            if (carried && strtof(x, NULL) == f) {
                memcpy(e, x, sizeof x);
            }
        }
    }
    /* e: [-]d[.ddd]e[+-]XX */
    m = e;
    if (*m == '-') {
        fputc('-', stdout);
        m++;
    }
    for (; *m && *m != 'e'; m++) {
        if (*m >= '0' && *m <= '9') {
            digits[nd++] = *m;
        }
    }
    exp10 = atoi(m + 1);
    while (nd > 1 && digits[nd - 1] == '0') {
        nd--;
    }
    if (nd == 1 && digits[0] == '0') {
        fputc('0', stdout);
        return;
    }
    if (exp10 >= 0) {
        for (i = 0; i <= exp10; i++) {
            fputc(i < nd ? digits[i] : '0', stdout);
        }
        if (nd > exp10 + 1) {
            fputc('.', stdout);
            for (i = exp10 + 1; i < nd; i++) {
                fputc(digits[i], stdout);
            }
        }
    } else {
        fputs("0.", stdout);
        for (i = 0; i < -exp10 - 1; i++) {
            fputc('0', stdout);
        }
        for (i = 0; i < nd; i++) {
            fputc(digits[i], stdout);
        }
    }
}

int main(int argc, char **argv)
{
    FILE *in = stdin;
    gl_decoder d;
    gl_frame f;
    int c, header = 0;
    if (argc > 1) {
        in = fopen(argv[1], "rb");
        if (!in) {
            perror(argv[1]);
            return 2;
        }
    }
    gl_decoder_init(&d);
    while ((c = fgetc(in)) != EOF) {
        const gl_sample *s;
        int a, i;
        if (gl_feed(&d, (uint8_t)c, &f) != GL_OK || f.kind != GL_SAMPLE) {
            continue;
        }
        s = &f.u.sample;
        if (!header) {
            fputs("link_seq,seq,t_us,age_x_us,age_y_us,age_z_us,predicted_us,x_dps,y_dps,z_dps,valid,degraded,"
                  "used_x,used_y,used_z",
                  stdout);
            for (i = 0; i < s->n_health; i++) {
                printf(",flags_%d", i);
            }
            fputs(",angle_x,angle_y,angle_z\n", stdout);
            header = 1;
        }
        printf("%lu,%lu,%llu", (unsigned long)f.link_seq, (unsigned long)s->seq, (unsigned long long)s->t_us);
        for (a = 0; a < 3; a++) {
            printf(",%u", (unsigned)s->age_us[a]);
        }
        fputc(',', stdout);
        if (s->has_predicted) {
            printf("%u", (unsigned)s->predicted_us);
        }
        for (a = 0; a < 3; a++) {
            fputc(',', stdout);
            print_f32(s->rate_dps[a]);
        }
        printf(",%u,%u", (unsigned)s->valid, (unsigned)s->degraded);
        for (a = 0; a < 3; a++) {
            printf(",%u", (unsigned)s->used[a]);
        }
        for (i = 0; i < s->n_health; i++) {
            printf(",%u", (unsigned)s->health[i]);
        }
        /* The integrated angle, 2^-32 turn (empty where not sent). */
        for (a = 0; a < 3; a++) {
            fputc(',', stdout);
            if (s->has_angle) {
                printf("%lu", (unsigned long)s->angle_turn32[a]);
            }
        }
        fputc('\n', stdout);
    }
    if (in != stdin) {
        fclose(in);
    }
    return 0;
}
