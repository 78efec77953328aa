/* Fuzzes the controller's receive path (mrs_rx_accept: length, E2E CRC, the cantools-generated
 * unpack, range checks, alive counter) with random and mutated frames.
 *
 *   fuzz_rx ITERATIONS [SEED]   random frames, valid frames and mutations of them; prints one
 *                               line of figures; exit 1 on any violated property
 *   fuzz_rx verdicts            reads "FRAME_ID HEX" lines (hex), prints mrs_rx_accept's verdict
 *                               for each (decimal), on one receiver: for differential tests
 *                               against mrsteer_dbc.link.RxLink
 *
 * Properties: no crash and no sanitizer report (build with make sanitize); every accepted frame
 * has the DBC length, a valid E2E CRC, a counter below 15 and a measurement inside its DBC range;
 * a frame made valid but out of range is rejected for RANGE; an unmutated valid frame that
 * continues its sequence is accepted (so the harness can fail). */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "mrs_dbc_e2e.h"
#include "mrs_e2e.h"
#include "mrs_rx.h"
#include "mrsteer.h"

static uint64_t rng_state = 88172645463325252ull;

static uint32_t rnd(void) /* xorshift64: reproducible from the seed */
{
    rng_state ^= rng_state << 13;
    rng_state ^= rng_state >> 7;
    rng_state ^= rng_state << 17;
    return (uint32_t)(rng_state >> 32);
}

static const uint32_t IDS[3] = {MRSTEER_MRS_DRIVER_STEER_FRAME_ID, MRSTEER_MRS_YAW_RATE_FRAME_ID,
                                MRSTEER_MRS_VEHICLE_SPEED_FRAME_ID};
static const size_t LENS[3] = {MRSTEER_MRS_DRIVER_STEER_LENGTH, MRSTEER_MRS_YAW_RATE_LENGTH,
                               MRSTEER_MRS_VEHICLE_SPEED_LENGTH};
static const uint16_t DATA_IDS[3] = {MRS_DRIVER_STEER_E2E_DATA_ID, MRS_YAW_RATE_E2E_DATA_ID,
                                     MRS_VEHICLE_SPEED_E2E_DATA_ID};

/* A valid frame of input i with alive counter c and a measurement drawn in [-1.2, 1.2] x its
 * range (so some are out of range: then *in_range is 0). Returns the length. */
static size_t make_frame(int i, uint8_t c, uint8_t *data, int *in_range)
{
    const double x = ((double)(rnd() % 2001u) / 1000.0 - 1.0) * 1.2;
    int n = -1;
    memset(data, 0, 8u);
    if (i == 0) {
        struct mrsteer_mrs_driver_steer_t m;
        mrsteer_mrs_driver_steer_init(&m);
        m.driver_steer_counter = c;
        m.driver_steer_angle = mrsteer_mrs_driver_steer_driver_steer_angle_encode(x * 0.7);
        *in_range = mrsteer_mrs_driver_steer_driver_steer_angle_is_in_range(m.driver_steer_angle);
        n = mrsteer_mrs_driver_steer_pack(data, &m, 8u);
    } else if (i == 1) {
        struct mrsteer_mrs_yaw_rate_t m;
        mrsteer_mrs_yaw_rate_init(&m);
        m.yaw_rate_counter = c;
        m.yaw_rate_yaw_rate = mrsteer_mrs_yaw_rate_yaw_rate_yaw_rate_encode(x * 3.0);
        *in_range = mrsteer_mrs_yaw_rate_yaw_rate_yaw_rate_is_in_range(m.yaw_rate_yaw_rate);
        n = mrsteer_mrs_yaw_rate_pack(data, &m, 8u);
    } else {
        struct mrsteer_mrs_vehicle_speed_t m;
        mrsteer_mrs_vehicle_speed_init(&m);
        m.vehicle_speed_counter = c;
        m.vehicle_speed_speed = mrsteer_mrs_vehicle_speed_vehicle_speed_speed_encode((x + 1.0) * 35.0);
        *in_range = mrsteer_mrs_vehicle_speed_vehicle_speed_speed_is_in_range(m.vehicle_speed_speed);
        n = mrsteer_mrs_vehicle_speed_pack(data, &m, 8u);
    }
    if (n != (int)LENS[i]) {
        fprintf(stderr, "fuzz_rx: pack failed for input %d\n", i);
        exit(2);
    }
    data[0] = mrs_e2e_crc(DATA_IDS[i], data, LENS[i], 0u);
    return LENS[i];
}

/* The property every accepted frame must have, checked from the frame itself. */
static int accepted_frame_is_sound(uint32_t id, const uint8_t *data, size_t len, const mrs_rx_frame_t *f)
{
    const int i = (int)f->input;
    const double lo[3] = {-0.7, -3.0, 0.0};
    const double hi[3] = {0.7, 3.0, 70.0};
    return id == IDS[i] && len == LENS[i] && data[0] == mrs_e2e_crc(DATA_IDS[i], data, len, 0u) &&
           (data[1] & 0x0Fu) < 15u && f->counter == (data[1] & 0x0Fu) && f->value >= lo[i] && f->value <= hi[i];
}

/* The MAC hook: "forged" while *ctx is nonzero (the MAC itself is the node's, not fuzzed here). */
static int mac_hook(void *ctx, uint32_t frame_id, const uint8_t *data, size_t len)
{
    (void)frame_id;
    (void)data;
    (void)len;
    return *(const int *)ctx == 0;
}

/* CtrlStatus_Cause bit of each verdict, from dbc/names.py, independent of mrs_rx_cause. */
static const uint8_t CAUSE[9] = {0u, 0u, 0x08u, 0x08u, 0x08u, 0x10u, 0x40u, 0x08u, 0x08u};

static int verdicts(void)
{
    mrs_rx_t rx;
    char hex[2u * 64u + 1u];
    unsigned id;
    mrs_rx_init(&rx, 3u, NULL, NULL);
    while (scanf("%x %128s", &id, hex) == 2) {
        uint8_t data[64];
        mrs_rx_frame_t f;
        size_t k, len = (strcmp(hex, "-") == 0) ? 0u : strlen(hex) / 2u;
        for (k = 0u; k < len; ++k) {
            unsigned b;
            if (sscanf(hex + 2u * k, "%2x", &b) != 1) {
                return 2;
            }
            data[k] = (uint8_t)b;
        }
        printf("%d\n", (int)mrs_rx_accept(&rx, (uint32_t)id, data, len, &f));
    }
    return 0;
}

int main(int argc, char **argv)
{
    mrs_rx_t rx;
    long n, k;
    long accepted = 0, rejected = 0, collisions = 0, valid_ok = 0, range_ok = 0, bad = 0;
    long by_verdict[9] = {0};
    uint8_t last[3] = {14u, 14u, 14u};
    if (argc >= 2 && strcmp(argv[1], "verdicts") == 0) {
        return verdicts();
    }
    if (argc < 2 || (n = strtol(argv[1], NULL, 10)) <= 0) {
        fprintf(stderr, "usage: fuzz_rx ITERATIONS [SEED] | fuzz_rx verdicts\n");
        return 2;
    }
    if (argc >= 3) {
        rng_state ^= (uint64_t)strtoull(argv[2], NULL, 10) * 0x9E3779B97F4A7C15ull;
    }
    if (mrs_crc8_sae_j1850((const uint8_t *)"123456789", 9u) != 0x4Bu) {
        fprintf(stderr, "fuzz_rx: CRC-8/SAE-J1850 check value wrong\n");
        return 1;
    }
    int forged = 0;
    mrs_rx_init(&rx, 3u, mac_hook, &forged);
    for (k = 0; k < n; ++k) {
        uint8_t data[16], orig[16];
        const int i = (int)(rnd() % 3u);
        const uint8_t c = mrs_e2e_next_counter(last[i]);
        const unsigned kind = rnd() % 10u;
        int in_range = 1;
        size_t len = make_frame(i, c, data, &in_range);
        uint32_t id = IDS[i];
        mrs_rx_frame_t f;
        mrs_rx_verdict_t v;
        memcpy(orig, data, sizeof orig);
        if (kind == 0u) { /* wholly random frame: any ID of ours or near it, any length */
            id = (rnd() % 4u == 0u) ? (rnd() & 0x7FFu) : IDS[rnd() % 3u];
            len = rnd() % 9u;
            for (size_t b = 0u; b < len; ++b) {
                data[b] = (uint8_t)rnd();
            }
        } else if (kind == 1u) { /* 1..4 bit flips */
            const unsigned flips = 1u + rnd() % 4u;
            for (unsigned b = 0u; b < flips; ++b) {
                data[rnd() % len] ^= (uint8_t)(1u << (rnd() % 8u));
            }
        } else if (kind == 2u) { /* one byte replaced */
            data[rnd() % len] = (uint8_t)rnd();
        } else if (kind == 3u) { /* wrong length */
            len = (len + 1u + rnd() % 7u) % 9u;
        } else if (kind == 4u) { /* counter 15 with a valid CRC */
            data[1] = (uint8_t)((data[1] & 0xF0u) | 0x0Fu);
            data[0] = mrs_e2e_crc(DATA_IDS[i], data, len, 0u);
        } else if (kind == 5u) { /* the same frame again: a repeated counter once accepted */
            /* unchanged */
        } else if (kind == 6u) { /* extended, remote or error flag */
            id |= (rnd() % 2u == 0u) ? MRS_RX_CAN_EFF_FLAG : MRS_RX_CAN_RTR_FLAG;
        } else if (kind == 8u) { /* forged: the MAC hook refuses it */
            forged = 1;
        } else if (kind == 9u) { /* the counter jumps by 5 (> max_delta 3) */
            data[1] = (uint8_t)((data[1] & 0xF0u) | ((c + 4u) % 15u));
            data[0] = mrs_e2e_crc(DATA_IDS[i], data, len, 0u);
        } /* kind 7: the valid frame as built */
        v = mrs_rx_accept(&rx, id, data, len, &f);
        forged = 0;
        ++by_verdict[v];
        if (mrs_rx_cause(v) != CAUSE[v]) {
            fprintf(stderr, "fuzz_rx: iteration %ld: verdict %d has cause %u\n", k, (int)v, (unsigned)mrs_rx_cause(v));
            ++bad;
        }
        if (kind == 8u && in_range) {
            /* a forgery must not advance the sequence: the same frame, authentic, is accepted */
            if (v != MRS_RX_MAC || mrs_rx_accept(&rx, id, data, len, &f) != MRS_RX_ACCEPTED) {
                fprintf(stderr, "fuzz_rx: iteration %ld: forged frame verdict %d or it advanced the counter\n", k,
                        (int)v);
                ++bad;
            }
            last[i] = c;
            ++rejected;
            continue;
        }
        if (v == MRS_RX_ACCEPTED) {
            ++accepted;
            if (!accepted_frame_is_sound(id, data, len, &f)) {
                fprintf(stderr, "fuzz_rx: iteration %ld: accepted an unsound frame\n", k);
                ++bad;
            }
            if (memcmp(data, orig, len) != 0 && kind != 0u) {
                ++collisions; /* a mutation the CRC did not catch: still sound, as checked above */
            }
            last[f.input] = f.counter;
        } else {
            ++rejected;
            if (v == MRS_RX_WRONG_SEQUENCE) { /* the receiver re-synchronised on this frame's counter */
                for (int j = 0; j < 3; ++j) {
                    last[j] = (id == IDS[j]) ? (uint8_t)(data[1] & 0x0Fu) : last[j];
                }
            }
        }
        if ((kind == 7u || kind == 5u) && in_range && id == IDS[i]) {
            if (kind == 7u && v != MRS_RX_ACCEPTED) {
                fprintf(stderr, "fuzz_rx: iteration %ld: a valid frame in sequence was rejected (%d)\n", k, (int)v);
                ++bad;
            }
            valid_ok += (v == MRS_RX_ACCEPTED) ? 1 : 0;
        }
        if ((kind == 7u) && !in_range) {
            if (v != MRS_RX_RANGE) {
                fprintf(stderr, "fuzz_rx: iteration %ld: an out-of-range frame got verdict %d\n", k, (int)v);
                ++bad;
            }
            ++range_ok;
        }
        if (kind == 5u && v == MRS_RX_ACCEPTED) {
            /* accepted once: the same frame a second time must be a repeat */
            const mrs_rx_verdict_t again = mrs_rx_accept(&rx, id, data, len, &f);
            ++by_verdict[again];
            if (again != MRS_RX_REPEATED) {
                fprintf(stderr, "fuzz_rx: iteration %ld: a repeated frame was not rejected as such\n", k);
                ++bad;
            }
        }
    }
    printf("fuzz_rx: iterations=%ld accepted=%ld rejected=%ld valid_accepted=%ld out_of_range_rejected=%ld "
           "crc_collisions_accepted=%ld ignored=%ld length=%ld crc=%ld counter_value=%ld range=%ld repeated=%ld "
           "wrong_sequence=%ld violations=%ld\n",
           n, accepted, rejected, valid_ok, range_ok, collisions, by_verdict[MRS_RX_IGNORED],
           by_verdict[MRS_RX_LENGTH], by_verdict[MRS_RX_CRC], by_verdict[MRS_RX_COUNTER_VALUE],
           by_verdict[MRS_RX_RANGE], by_verdict[MRS_RX_REPEATED], by_verdict[MRS_RX_WRONG_SEQUENCE], bad);
    return bad == 0 ? 0 : 1;
}
