/* Fuzzes the C node's receive chain: mrs_node_accept (mrs_node_rx.c), the function mrs_node
 * runs on every received frame, on a node set up as mrs_node sets it up, with random and
 * mutated frames of every message the node takes (the three sensor messages,
 * MRS_RedundantSensors and, keyed, MRS_SecOCSync).
 *
 *   fuzz_rx ITERATIONS [SEED [KEYHEX32]]   random frames, authentic frames and mutations of
 *                                           them; keyed: SecOC on, with syncs, forgeries and
 *                                           replays. One line of figures; exit 1 on any violation
 *   fuzz_rx verdicts [KEYHEX32]            reads "FRAME_ID HEX" lines (hex; "-" for no data)
 *                                           and prints each frame's verdict (mrs_rx_verdict_t,
 *                                           decimal) on one node: for differential tests
 *                                           against the Python controller's RxLink
 *
 * What "corrupt" means is decided by the fuzzer's own model (fuzz_oracle.c), not by the code
 * under test.
 * Every verdict is checked against that model: a rejection must be the first check the frame
 * fails; an accepted frame (or one whose MAC passed) must have a MAC that verifies for a
 * freshness value past its message's last one, in an epoch of an authentic sync, and an alive
 * counter 1..3 past the last one the receiver took. Authentic frames in step must be accepted,
 * forged MACs refused without advancing anything, repeats and replayed syncs refused (so the
 * harness can fail). Mutations a check cannot see (the 8-bit CRC, an 8-bit MAC) are counted. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fuzz_oracle.h"
#include "mrs_contract.h"
#include "mrs_node_core.h"

#define HISTORY 32

static uint64_t rng_state = 88172645463325252ull;

static uint32_t rnd(void) /* xorshift64: reproducible from the seed */
{
    rng_state ^= rng_state << 13;
    rng_state ^= rng_state >> 7;
    rng_state ^= rng_state << 17;
    return (uint32_t)(rng_state >> 32);
}

/* ---- the sender: authentic frames, then mutations ---- */

typedef struct {
    unsigned alive; /* the last alive counter sent */
    uint32_t fv; /* the next freshness counter in `epoch` */
    uint64_t epoch;
    int in_step; /* the node took an authentic frame of this input, and nothing moved it on since */
    unsigned gap; /* frames sent since the last one the node took */
    uint64_t taken_epoch; /* the epoch of that frame */
    uint8_t hist[HISTORY][8];
    uint64_t hist_epoch[HISTORY];
    unsigned n_hist;
} sender_t;

static double draw(const mrs_msg_t *m, int sig)
{
    const double lo = m->min[sig], hi = m->max[sig], span = hi - lo;
    const double lower = lo < 0.0 ? lo - 0.02 * span : lo; /* below 0 only where the raw field is signed */
    return lower + (hi + 0.02 * span - lower) * (double)(rnd() % 10001u) / 10000.0;
}

/* An authentic frame of input k (signed for (epoch, fv) when sign; MAC `mac_xor`ed); its length. */
static size_t build(const mrs_node_t *n, int k, unsigned alive, int sign, uint64_t epoch, uint32_t fv,
                    uint64_t mac_xor, uint8_t d[8])
{
    const mrs_msg_t *m = &mrs_messages[MSGS[k]];
    const mrs_input_t *in = &n->in[k];
    double phys[MRS_MAX_SIGNALS] = {0.0};
    ref_t r;
    int j;
    phys[m->counter] = (double)alive;
    phys[in->sig] = draw(m, in->sig);
    for (j = 0; j < MRS_INPUT_EXTRA; ++j) {
        const int s = in->extra_sig[j];
        if (s >= 0) {
            /* a signal with an SNA value: sometimes that (NaN packs as it) */
            phys[s] = (m->sna[s] != 0u && rnd() % 8u == 0u) ? (double)NAN : draw(m, s);
        }
    }
    if (sign) {
        phys[m->fv_epoch] = (double)(epoch & 1u);
        phys[m->fv_counter] = (double)(fv & ((1u << m->fv_counter_bits) - 1u));
    }
    memset(d, 0, 8u);
    if (m->pack(d, 8u, phys) != (int)LENS[k]) {
        fprintf(stderr, "fuzz_rx: pack failed for message %d\n", k);
        exit(2);
    }
    if (sign && ref_decode(k, d, LENS[k], &r) == 0) {
        phys[m->mac] = (double)(ref_mac(IDS[k], r.zeroed, LENS[k], (epoch << 24) | fv, m->mac_bits) ^ mac_xor);
        (void)m->pack(d, 8u, phys);
    }
    d[m->crc_byte] = ref_crc(m->data_id, d, LENS[k], m->crc_byte);
    return LENS[k];
}

static size_t build_sync(uint64_t epoch, uint8_t d[8])
{
    const mrs_msg_t *m = &mrs_messages[MRS_MSG_SYNC];
    double phys[MRS_MAX_SIGNALS] = {0.0};
    uint8_t none[1] = {0u};
    phys[m->epoch] = (double)epoch;
    phys[m->mac] = (double)ref_mac(IDS[K_SYNC], none, 0u, epoch, m->mac_bits);
    memset(d, 0, 8u);
    return (size_t)m->pack(d, 8u, phys);
}

typedef struct {
    long valid_checked, valid_accepted, crc_collisions, mac_collisions, reached_mac, forged_refused, replays,
        replays_refused, syncs_accepted, syncs_rejected, sensor_rejected, sensor_mac, bad;
    long by_verdict[9];
} figures_t;

static mrs_node_t node;
static figures_t fg;
static sender_t snd[N_IN];
static int keyed;
static uint64_t sender_epoch; /* the epoch of the last authentic sync sent; 0: none yet */

/* One frame through the node's chain, judged; *slot and *r as ref_verdict gives them. */
static mrs_rx_verdict_t send(uint32_t id, uint8_t flags, const uint8_t *d, size_t len, long it, int *slot, ref_t *r)
{
    mrs_frame_t f;
    mrs_rx_verdict_t v, rv;
    memset(&f, 0, sizeof f);
    f.id = id;
    f.flags = flags;
    f.len = (uint8_t)len;
    memcpy(f.data, d, len);
    v = mrs_node_accept(&node, &f);
    rv = ref_verdict(keyed, id, flags, d, len, slot, r);
    fg.bad += oracle_judge(&node, v, rv, *slot, r, keyed, it);
    ++fg.by_verdict[v];
    if (*slot >= 0 && *slot < N_IN && v != MRS_RX_IGNORED && v != MRS_RX_ACCEPTED) {
        ++fg.sensor_rejected;
        fg.sensor_mac += v == MRS_RX_MAC ? 1 : 0;
    }
    if (*slot == K_SYNC && v != MRS_RX_IGNORED) {
        fg.syncs_rejected += v != MRS_RX_ACCEPTED ? 1 : 0;
    }
    return v;
}

static int reached_sequence(mrs_rx_verdict_t v)
{
    return v == MRS_RX_ACCEPTED || v == MRS_RX_REPEATED || v == MRS_RX_WRONG_SEQUENCE;
}

/* An authentic new epoch (accepted), a forged one or a replayed one (refused). */
static void sync_event(long it)
{
    const unsigned kind = it == 0 ? 0u : rnd() % 4u;
    uint8_t d[8];
    ref_t r;
    int slot;
    size_t len;
    mrs_rx_verdict_t v;
    if (kind <= 1u) {
        const uint64_t e = sender_epoch == 0u ? 1000000u : sender_epoch + 1u;
        len = build_sync(e, d);
        if (send(IDS[K_SYNC], 0u, d, len, it, &slot, &r) != MRS_RX_ACCEPTED) {
            fg.bad += oracle_fail(it, "an authentic new sync was refused", K_SYNC, 0);
        }
        sender_epoch = e;
        ++fg.syncs_accepted;
    } else if (kind == 2u) {
        const unsigned bit = rnd() % (8u * LENS[K_SYNC]);
        len = build_sync(sender_epoch + 1u, d);
        d[bit / 8u] ^= (uint8_t)(1u << (bit % 8u));
        if (send(IDS[K_SYNC], 0u, d, len, it, &slot, &r) == MRS_RX_ACCEPTED) {
            fg.bad += oracle_fail(it, "a forged sync was accepted", K_SYNC, 0);
        }
    } else if (sender_epoch != 0u) {
        len = build_sync(sender_epoch - (rnd() % 2u), d); /* the current epoch again, or the one before */
        v = send(IDS[K_SYNC], 0u, d, len, it, &slot, &r);
        fg.bad += v != MRS_RX_MAC ? oracle_fail(it, "a replayed sync was not refused", K_SYNC, (int)v) : 0;
    }
}

static unsigned replay_back; /* how many frames back the last replay went (1: the frame just built) */
static uint64_t replay_epoch; /* the epoch it was signed for */

/* The mutation `kind` of input k's authentic frame base into d; its length (0..8), *id, *flags. */
static size_t mutate(int k, unsigned kind, const uint8_t *base, size_t len, int sign, uint8_t *d, uint32_t *id,
                     uint8_t *flags)
{
    const mrs_msg_t *m = &mrs_messages[MSGS[k]];
    sender_t *s = &snd[k];
    double phys[MRS_MAX_SIGNALS];
    unsigned b;
    memcpy(d, base, 8u);
    if (kind == 0u) { /* wholly random: any of our IDs or another, any length */
        *id = (rnd() % 4u == 0u) ? (rnd() & 0x7FFu) : IDS[rnd() % 5u];
        len = rnd() % 9u;
        for (b = 0u; b < 8u; ++b) {
            d[b] = (uint8_t)rnd();
        }
    } else if (kind == 1u) { /* 1..4 bit flips */
        const unsigned flips = 1u + rnd() % 4u;
        for (b = 0u; b < flips; ++b) {
            d[rnd() % len] ^= (uint8_t)(1u << (rnd() % 8u));
        }
    } else if (kind == 2u) { /* one byte replaced */
        d[rnd() % len] = (uint8_t)rnd();
    } else if (kind == 3u) { /* another length */
        len = (len + 1u + rnd() % 7u) % 9u;
    } else if (kind == 4u) { /* alive counter 15 with a valid CRC (and MAC) */
        len = build(&node, k, 15u, sign, s->epoch, s->fv - 1u, 0u, d);
    } else if (kind == 6u) { /* an extended, remote or error frame */
        *flags = (uint8_t)(1u << (rnd() % 3u));
    } else if (kind == 8u && sign) { /* a forged MAC (CRC valid) */
        len = build(&node, k, s->alive, sign, s->epoch, s->fv - 1u, 1u + rnd() % ((1u << m->mac_bits) - 1u), d);
    } else if (kind == 10u && s->n_hist >= 2u) { /* an earlier frame of this input replayed */
        replay_back = 2u + rnd() % ((s->n_hist < HISTORY ? s->n_hist : HISTORY) - 1u);
        memcpy(d, s->hist[(s->n_hist - replay_back) % HISTORY], 8u);
        replay_epoch = s->hist_epoch[(s->n_hist - replay_back) % HISTORY];
    } else if (kind == 11u || kind == 8u) { /* the measurement changed, the CRC made valid, the MAC kept */
        if (m->unpack(phys, base, len) == 0) {
            phys[node.in[k].sig] = draw(m, node.in[k].sig);
            (void)m->pack(d, 8u, phys);
            d[m->crc_byte] = ref_crc(m->data_id, d, len, m->crc_byte);
        }
    }
    return len;
}

/* What the node must do with an authentic frame in step: gap frames lost since the one it took. */
static int in_step(const sender_t *s, unsigned gap, int sign, uint32_t fv)
{
    return s->in_step && gap <= MAX_DELTA && (!sign || s->taken_epoch == s->epoch || fv < 8u);
}

static void sensor_event(long it)
{
    const int k = (int)(rnd() % (unsigned)N_IN);
    const unsigned kind = rnd() % 14u; /* 7, 12, 13: the authentic frame as built */
    const int sign = keyed && sender_epoch != 0u;
    sender_t *s = &snd[k];
    uint8_t base[8], d[8], flags = 0u;
    uint32_t id = IDS[k], fv;
    size_t len, dlen;
    ref_t r, rb;
    int slot, base_ok, mutated, expect, forged;
    mrs_rx_verdict_t v;
    if (s->epoch != sender_epoch) {
        s->epoch = sender_epoch;
        s->fv = 0u;
    }
    s->gap += kind == 9u ? 5u : 1u; /* kind 9: four frames lost on the bus */
    s->fv += kind == 9u ? 4u : 0u;
    fv = s->fv;
    s->alive = (s->alive + (kind == 9u ? 5u : 1u)) % ALIVE_MOD;
    len = build(&node, k, s->alive, sign, s->epoch, fv, 0u, base);
    ++s->fv;
    s->hist_epoch[s->n_hist % HISTORY] = s->epoch;
    memcpy(s->hist[s->n_hist++ % HISTORY], base, 8u);
    base_ok = ref_verdict(keyed, id, 0u, base, len, &slot, &rb) == MRS_RX_ACCEPTED;
    expect = in_step(s, s->gap, sign, fv) && base_ok;
    dlen = mutate(k, kind, base, len, sign, d, &id, &flags);
    mutated = id != IDS[k] || flags != 0u || dlen != len || memcmp(d, base, len) != 0;
    v = send(id, flags, d, dlen, it, &slot, &r);
    forged = mutated && slot == k && flags == 0u && (kind == 1u || kind == 2u || kind == 11u) &&
             ref_verdict(keyed, id, 0u, d, dlen, &slot, &r) == MRS_RX_ACCEPTED; /* only a MAC can refuse it */
    if (mutated && slot >= 0 && slot < N_IN && reached_sequence(v)) {
        snd[slot].in_step = 0; /* a frame the CRC (and MAC) did not catch moved that input on */
        fg.crc_collisions += (!keyed && slot == k && (kind == 1u || kind == 2u)) ? 1 : 0;
        fg.mac_collisions += (keyed && forged) ? 1 : 0;
    }
    fg.reached_mac += (keyed && forged) ? 1 : 0;
    if (kind == 10u && keyed && s->n_hist >= 2u && s->in_step && replay_back > s->gap &&
        replay_epoch == s->taken_epoch) {
        /* a frame of the epoch the node took one in, as old as that one or older: refused by the
         * freshness window before any MAC (an older epoch's is refused by its MAC: 1 in 256 passes) */
        ++fg.replays;
        fg.replays_refused += reached_sequence(v) ? 0 : 1;
        fg.bad += reached_sequence(v) ? oracle_fail(it, "a replayed frame passed its MAC", k, (int)v) : 0;
    }
    if (kind == 8u && sign && ref_verdict(keyed, id, 0u, d, dlen, &slot, &r) == MRS_RX_ACCEPTED) {
        /* A forged MAC on a frame otherwise sound: in step, the node verifies it for the FV it
         * was forged for, so it must be refused for its MAC and nothing moved on; out of step
         * it is checked for another FV, which an 8-bit MAC passes 1 time in 256. */
        if (expect) {
            fg.bad += v != MRS_RX_MAC ? oracle_fail(it, "a forged MAC was not refused for MAC", k, (int)v) : 0;
            fg.forged_refused += v == MRS_RX_MAC ? 1 : 0;
        } else if (reached_sequence(v)) {
            s->in_step = 0;
        }
        v = send(IDS[k], 0u, base, len, it, &slot, &r);
        mutated = 0;
    }
    if ((kind == 7u || kind == 12u || kind == 13u || kind == 8u) && expect && !mutated) {
        ++fg.valid_checked;
        fg.valid_accepted += v == MRS_RX_ACCEPTED ? 1 : 0;
        fg.bad += v != MRS_RX_ACCEPTED ? oracle_fail(it, "an authentic frame in step was refused", k, (int)v) : 0;
    }
    if (kind == 9u && s->in_step && s->gap < ALIVE_MOD && base_ok && (!sign || s->taken_epoch == s->epoch || fv < 8u)) {
        fg.bad += v != MRS_RX_WRONG_SEQUENCE ? oracle_fail(it, "a counter jump of 5 was not WRONG_SEQUENCE", k, (int)v) : 0;
    }
    if (kind == 5u) { /* the same frame again: never taken twice */
        const mrs_rx_verdict_t again = send(IDS[k], 0u, base, len, it, &slot, &r);
        if (again == MRS_RX_ACCEPTED || (!keyed && v == MRS_RX_ACCEPTED && again != MRS_RX_REPEATED)) {
            fg.bad += oracle_fail(it, "a repeated frame was not refused as such", k, (int)again);
        }
    }
    if (!mutated && (v == MRS_RX_ACCEPTED || v == MRS_RX_WRONG_SEQUENCE)) {
        /* Taken (otherwise one more frame lost: the gap stays); in step if for the FV it was
         * signed for (an 8-bit MAC passes another one time in 256). */
        const mrs_sensor_last_t *last = &node.verifier.last[MSGS[k]];
        s->in_step = !sign || (last->epoch == s->epoch && last->counter == fv);
        s->gap = 0u;
        s->taken_epoch = s->epoch;
    }
}

/* mrs_node_receive, what mrs_node.c calls on every frame: 1 for an accepted yaw-rate frame, 0
 * for another accepted one. The node's first frames of the two inputs, authentic and in range. */
static void receive_check(void)
{
    static const int inputs[2] = {1, 0}; /* yaw rate, driver angle */
    const int sign = keyed && sender_epoch != 0u;
    int i;
    for (i = 0; i < 2; ++i) {
        const int k = inputs[i];
        sender_t *s = &snd[k];
        const uint64_t rejected = node.stats.rx_rejected;
        uint8_t d[8];
        ref_t r;
        int slot, got;
        mrs_frame_t f;
        s->epoch = sender_epoch;
        s->alive = 1u;
        do { /* until the measurement drawn is in range */
            (void)build(&node, k, s->alive, sign, s->epoch, 0u, 0u, d);
        } while (ref_verdict(keyed, IDS[k], 0u, d, LENS[k], &slot, &r) != MRS_RX_ACCEPTED);
        memset(&f, 0, sizeof f);
        f.id = IDS[k];
        f.len = (uint8_t)LENS[k];
        memcpy(f.data, d, LENS[k]);
        got = mrs_node_receive(&node, &f);
        if (got != (k == 1 ? 1 : 0) || node.stats.rx_rejected != rejected) {
            fg.bad += oracle_fail(0, "mrs_node_receive on a first authentic frame", k, got);
        }
        fg.bad += oracle_judge(&node, MRS_RX_ACCEPTED, MRS_RX_ACCEPTED, k, &r, keyed, 0);
        ++fg.by_verdict[MRS_RX_ACCEPTED];
        s->fv = 1u;
        s->in_step = 1;
        s->gap = 0u;
        s->taken_epoch = s->epoch;
        s->hist_epoch[0] = s->epoch;
        memcpy(s->hist[0], d, 8u);
        s->n_hist = 1u;
    }
}

static int hex_bytes(const char *hex, uint8_t *out, size_t max)
{
    size_t n = 0u;
    unsigned b;
    if (strcmp(hex, "-") == 0) {
        return 0;
    }
    while (n < max && hex[2u * n] != '\0' && hex[2u * n + 1u] != '\0' && sscanf(hex + 2u * n, "%2x", &b) == 1) {
        out[n++] = (uint8_t)b;
    }
    return (int)n;
}

static int setup(const char *key_hex, uint8_t key[16])
{
    mrs_node_config_t cfg;
    static mrs_bus_t bus; /* the receive chain sends nothing */
    char err[256];
    memset(&cfg, 0, sizeof cfg);
    cfg.rate_hz = 500.0;
    cfg.timeout_cycles = 10;
    cfg.e2e_fail_max = 3;
    cfg.max_counter_delta = (int)MAX_DELTA;
    mrs_default_config(&cfg.controller);
    keyed = key_hex != NULL;
    if (keyed) {
        if (hex_bytes(key_hex, key, 16u) != 16 || ref_key(key) != 0) {
            fprintf(stderr, "fuzz_rx: the key must be 32 hex digits (and OpenSSL have AES-CMAC)\n");
            return -1;
        }
        cfg.secoc_key = key;
    }
    if (mrs_node_init(&node, &bus, &cfg, err, sizeof err) != 0) {
        fprintf(stderr, "fuzz_rx: %s\n", err);
        return -1;
    }
    return 0;
}

static int verdicts(void)
{
    char hex[2u * 64u + 1u];
    unsigned id;
    while (scanf("%x %128s", &id, hex) == 2) {
        mrs_frame_t f;
        memset(&f, 0, sizeof f);
        f.id = (uint32_t)id;
        f.len = (uint8_t)hex_bytes(hex, f.data, sizeof f.data);
        printf("%d\n", (int)mrs_node_accept(&node, &f));
    }
    return 0;
}

/* The receive filters are the IDs of the cantools codec's messages, in the node's order. */
static long filters_sound(void)
{
    uint32_t ids[8];
    const size_t n = mrs_node_filter_ids(keyed, ids);
    size_t i;
    long bad = n != (keyed ? 5u : 4u) ? 1 : 0;
    for (i = 0u; i < n && i < 5u; ++i) {
        bad += ids[i] != IDS[i] ? 1 : 0;
    }
    return bad != 0 ? oracle_fail(-1, "receive filters", -1, 0) : 0;
}

int main(int argc, char **argv)
{
    uint8_t key[16];
    long n, it;
    const int verdict_mode = argc >= 2 && strcmp(argv[1], "verdicts") == 0;
    if (verdict_mode) {
        return setup(argc >= 3 ? argv[2] : NULL, key) != 0 ? 2 : verdicts();
    }
    if (argc < 2 || (n = strtol(argv[1], NULL, 10)) <= 0) {
        fprintf(stderr, "usage: fuzz_rx ITERATIONS [SEED [KEYHEX32]] | fuzz_rx verdicts [KEYHEX32]\n");
        return 2;
    }
    if (argc >= 3) {
        rng_state ^= (uint64_t)strtoull(argv[2], NULL, 10) * 0x9E3779B97F4A7C15ull;
    }
    if (setup(argc >= 4 ? argv[3] : NULL, key) != 0) {
        return 2;
    }
    fg.bad += filters_sound();
    if (mrs_crc8_sae_j1850((const uint8_t *)"123456789", 9u) != 0x4Bu) { /* its standard check value */
        fg.bad += oracle_fail(-1, "CRC-8/SAE-J1850 check value", -1, 0);
    }
    if (keyed) {
        sync_event(0);
    }
    receive_check();
    for (it = 1; it < n; ++it) {
        if (keyed && rnd() % 64u == 0u) {
            sync_event(it);
        } else {
            sensor_event(it);
        }
    }
    if ((uint64_t)fg.sensor_rejected != node.stats.rx_rejected || (uint64_t)fg.sensor_mac != node.stats.rx_auth_failed + node.stats.rx_unsynced ||
        (uint64_t)fg.syncs_rejected != node.stats.syncs_rejected) {
        fg.bad += oracle_fail(n, "the node's rejection counters differ from its verdicts", -1, 0);
    }
    printf("fuzz_rx: mode=%s iterations=%ld accepted=%ld valid_checked=%ld valid_accepted=%ld "
           "crc_collisions_accepted=%ld forgeries_reaching_mac=%ld mac_collisions_accepted=%ld forged_mac_refused=%ld "
           "replays=%ld replays_refused=%ld syncs_accepted=%ld ignored=%ld length=%ld crc=%ld counter_value=%ld "
           "range=%ld mac=%ld repeated=%ld wrong_sequence=%ld violations=%ld\n",
           keyed ? "keyed" : "plain", n, fg.by_verdict[MRS_RX_ACCEPTED], fg.valid_checked, fg.valid_accepted,
           fg.crc_collisions, fg.reached_mac, fg.mac_collisions, fg.forged_refused, fg.replays, fg.replays_refused,
           fg.syncs_accepted, fg.by_verdict[MRS_RX_IGNORED], fg.by_verdict[MRS_RX_LENGTH], fg.by_verdict[MRS_RX_CRC],
           fg.by_verdict[MRS_RX_COUNTER_VALUE], fg.by_verdict[MRS_RX_RANGE], fg.by_verdict[MRS_RX_MAC],
           fg.by_verdict[MRS_RX_REPEATED], fg.by_verdict[MRS_RX_WRONG_SEQUENCE], fg.bad);
    mrs_node_free(&node);
    ref_free();
    return fg.bad == 0 ? 0 : 1;
}
