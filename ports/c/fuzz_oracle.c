/* The fuzzer's independent model of the node's receive chain (fuzz_oracle.h). */
#include "fuzz_oracle.h"

#include <openssl/core_names.h>
#include <openssl/evp.h>
#include <openssl/params.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "mrsteer.h"

const uint32_t IDS[5] = {MRSTEER_MRS_DRIVER_STEER_FRAME_ID, MRSTEER_MRS_YAW_RATE_FRAME_ID,
                         MRSTEER_MRS_VEHICLE_SPEED_FRAME_ID, MRSTEER_MRS_REDUNDANT_SENSORS_FRAME_ID,
                         MRSTEER_MRS_SEC_OC_SYNC_FRAME_ID};
const size_t LENS[5] = {MRSTEER_MRS_DRIVER_STEER_LENGTH, MRSTEER_MRS_YAW_RATE_LENGTH,
                        MRSTEER_MRS_VEHICLE_SPEED_LENGTH, MRSTEER_MRS_REDUNDANT_SENSORS_LENGTH,
                        MRSTEER_MRS_SEC_OC_SYNC_LENGTH};
const int MSGS[5] = {MRS_MSG_STEER, MRS_MSG_YAW, MRS_MSG_SPEED, MRS_MSG_REDUNDANT, MRS_MSG_SYNC};
/* CtrlStatus_Cause of each verdict, from dbc/names.py (E2E 0x08, RANGE 0x10, AUTH 0x40). */
static const unsigned CAUSE[9] = {0u, 0u, 0x08u, 0x08u, 0x08u, 0x10u, 0x40u, 0x08u, 0x08u};

uint8_t ref_crc(uint16_t data_id, const uint8_t *d, size_t len, size_t crc_byte)
{
    uint8_t bytes[2 + 64], r = 0u;
    size_t n = 0u, i;
    int b;
    bytes[n++] = (uint8_t)(data_id & 0xFFu);
    bytes[n++] = (uint8_t)(data_id >> 8);
    for (i = 0u; i < len; ++i) {
        if (i != crc_byte) {
            bytes[n++] = d[i];
        }
    }
    for (i = 0u; i < n; ++i) {
        r ^= bytes[i];
        for (b = 0; b < 8; ++b) {
            r = (uint8_t)((r & 0x80u) ? (((unsigned)r << 1) ^ 0x1Du) : ((unsigned)r << 1));
        }
    }
    return r;
}

#define IR(msg, pre, sig) mrsteer_##msg##_##pre##_##sig##_is_in_range(m.pre##_##sig)
#define REF_SENSOR(fn, msg, pre, MEASURED_IN_RANGE)                                                          \
    static int fn(const uint8_t *d, size_t len, ref_t *r)                                                    \
    {                                                                                                         \
        struct mrsteer_##msg##_t m;                                                                           \
        if (mrsteer_##msg##_unpack(&m, d, len) != 0) {                                                        \
            return -1;                                                                                        \
        }                                                                                                     \
        r->counter = m.pre##_counter;                                                                         \
        r->fv_epoch = m.pre##_fv_epoch;                                                                       \
        r->fv_counter = m.pre##_fv_counter;                                                                   \
        r->mac = m.pre##_mac;                                                                                 \
        r->in_range = IR(msg, pre, crc) && IR(msg, pre, counter) && IR(msg, pre, fv_epoch) &&                 \
                      IR(msg, pre, fv_counter) && IR(msg, pre, mac) && (MEASURED_IN_RANGE);                   \
        m.pre##_crc = 0u;                                                                                     \
        m.pre##_mac = 0u;                                                                                     \
        memset(r->zeroed, 0, sizeof r->zeroed);                                                               \
        return mrsteer_##msg##_pack(r->zeroed, &m, sizeof r->zeroed) < 0 ? -1 : 0;                            \
    }

REF_SENSOR(ref_steer, mrs_driver_steer, driver_steer, IR(mrs_driver_steer, driver_steer, angle))
/* The second element's SNA (the DBC's value table) is no range error: it says "not available". */
REF_SENSOR(ref_yaw, mrs_yaw_rate, yaw_rate,
           IR(mrs_yaw_rate, yaw_rate, yaw_rate) &&
               (IR(mrs_yaw_rate, yaw_rate, yaw_rate2) ||
                m.yaw_rate_yaw_rate2 == MRSTEER_MRS_YAW_RATE_YAW_RATE_YAW_RATE2_SNA_CHOICE))
REF_SENSOR(ref_speed, mrs_vehicle_speed, vehicle_speed, IR(mrs_vehicle_speed, vehicle_speed, speed))
/* So is the second speed's. */
REF_SENSOR(ref_red, mrs_redundant_sensors, redundant_sensors,
           IR(mrs_redundant_sensors, redundant_sensors, lat_accel) &&
               IR(mrs_redundant_sensors, redundant_sensors, steer_angle) &&
               (IR(mrs_redundant_sensors, redundant_sensors, speed2) ||
                m.redundant_sensors_speed2 == MRSTEER_MRS_REDUNDANT_SENSORS_REDUNDANT_SENSORS_SPEED2_SNA_CHOICE))

static int ref_sync(const uint8_t *d, size_t len, ref_t *r)
{
    struct mrsteer_mrs_sec_oc_sync_t m;
    if (mrsteer_mrs_sec_oc_sync_unpack(&m, d, len) != 0) {
        return -1;
    }
    r->epoch = m.sec_oc_sync_epoch;
    r->mac = m.sec_oc_sync_mac;
    r->in_range = IR(mrs_sec_oc_sync, sec_oc_sync, epoch) && IR(mrs_sec_oc_sync, sec_oc_sync, mac);
    return 0;
}

static int (*const REFS[5])(const uint8_t *, size_t, ref_t *) = {ref_steer, ref_yaw, ref_speed, ref_red, ref_sync};

int ref_decode(int k, const uint8_t *d, size_t len, ref_t *r)
{
    return REFS[k](d, len, r);
}

static EVP_MAC_CTX *ref_mac_ctx; /* OpenSSL's AES-128-CMAC, keyed once */

void ref_free(void)
{
    EVP_MAC_CTX_free(ref_mac_ctx);
    ref_mac_ctx = NULL;
}

int ref_key(const uint8_t key[16])
{
    char cipher[] = "AES-128-CBC";
    OSSL_PARAM params[2];
    EVP_MAC *mac = EVP_MAC_fetch(NULL, "CMAC", NULL);
    params[0] = OSSL_PARAM_construct_utf8_string(OSSL_MAC_PARAM_CIPHER, cipher, 0u);
    params[1] = OSSL_PARAM_construct_end();
    ref_mac_ctx = mac != NULL ? EVP_MAC_CTX_new(mac) : NULL;
    EVP_MAC_free(mac);
    return ref_mac_ctx != NULL && EVP_MAC_init(ref_mac_ctx, key, 16u, params) == 1 ? 0 : -1;
}

static void put_be(uint8_t *p, uint64_t x, unsigned n)
{
    unsigned i;
    for (i = 0u; i < n; ++i) {
        p[i] = (uint8_t)(x >> (8u * (n - 1u - i)));
    }
}

/* The leading `bits` of the CMAC of frame ID (2 bytes) || body || tail (8 bytes), big-endian. */
uint64_t ref_mac(uint32_t id, const uint8_t *body, size_t len, uint64_t tail, unsigned bits)
{
    uint8_t buf[2 + 8 + 8], out[16];
    size_t out_len = 0u;
    uint64_t lead = 0u;
    int i;
    EVP_MAC_CTX *ctx = EVP_MAC_CTX_dup(ref_mac_ctx);
    put_be(buf, id, 2u);
    memcpy(buf + 2, body, len);
    put_be(buf + 2 + len, tail, 8u);
    if (ctx == NULL || EVP_MAC_update(ctx, buf, 2u + len + 8u) != 1 || EVP_MAC_final(ctx, out, &out_len, 16u) != 1) {
        fprintf(stderr, "fuzz_rx: OpenSSL CMAC failed\n");
        exit(2);
    }
    EVP_MAC_CTX_free(ctx);
    for (i = 0; i < 8; ++i) {
        lead = (lead << 8) | out[i];
    }
    return lead >> (64u - bits);
}

/* The first check of the chain the frame fails before MAC and sequence (ACCEPTED: none); *slot
 * gets its index in IDS, -1 if it is not one of the node's. */
mrs_rx_verdict_t ref_verdict(int keyed, uint32_t id, uint8_t flags, const uint8_t *d, size_t len, int *slot,
                                    ref_t *r)
{
    const mrs_msg_t *m;
    int k = -1, j;
    for (j = 0; j < 5; ++j) {
        if (id == IDS[j] && (j < N_IN || keyed)) {
            k = j;
        }
    }
    *slot = k;
    if (k < 0 || flags != 0u) {
        return MRS_RX_IGNORED;
    }
    m = &mrs_messages[MSGS[k]];
    if (len != LENS[k]) {
        return MRS_RX_LENGTH;
    }
    if (k < N_IN && d[m->crc_byte] != ref_crc(m->data_id, d, len, m->crc_byte)) {
        return MRS_RX_CRC;
    }
    if (REFS[k](d, len, r) != 0) {
        return MRS_RX_LENGTH;
    }
    if (k < N_IN && r->counter >= ALIVE_MOD) {
        return MRS_RX_COUNTER_VALUE;
    }
    return r->in_range ? MRS_RX_ACCEPTED : MRS_RX_RANGE;
}

/* What the node must have taken so far: each input's last alive counter at its sequence check
 * and last verified freshness value, the epochs of the authentic syncs it adopted. */
typedef struct {
    int have_alive, have_fv;
    unsigned alive;
    uint64_t fv_epoch, fv_counter;
} model_in_t;

static struct {
    model_in_t in[N_IN];
    int have_epoch, have_prev;
    uint64_t epoch, prev;
} model;

long oracle_fail(long it, const char *what, int k, int v)
{
    fprintf(stderr, "fuzz_rx: iteration %ld: %s (message %d, verdict %d)\n", it, what, k, v);
    return 1;
}

/* A sensor frame whose MAC passed: the freshness value the node verified it for must be sound. */
static long fv_sound(const mrs_node_t *n, int k, const ref_t *r, long it)
{
    const mrs_msg_t *m = &mrs_messages[MSGS[k]];
    const mrs_sensor_last_t *last = &n->verifier.last[MSGS[k]];
    model_in_t *mi = &model.in[k];
    const uint64_t fv = (last->epoch << 24) | last->counter;
    long bad = 0;
    if (ref_mac(IDS[k], r->zeroed, LENS[k], fv, m->mac_bits) != r->mac) {
        bad += oracle_fail(it, "MAC does not verify for the freshness value taken", k, 0);
    }
    if (!model.have_epoch || (last->epoch != model.epoch && !(model.have_prev && last->epoch == model.prev))) {
        bad += oracle_fail(it, "freshness epoch not of an authentic sync", k, 0);
    }
    if ((last->epoch & 1u) != r->fv_epoch || (last->counter & ((1u << m->fv_counter_bits) - 1u)) != r->fv_counter) {
        bad += oracle_fail(it, "freshness value does not match the frame's FV fields", k, 0);
    }
    if (mi->have_fv && !(last->epoch > mi->fv_epoch ||
                         (last->epoch == mi->fv_epoch && last->counter > mi->fv_counter &&
                          last->counter - mi->fv_counter <= 15u))) {
        bad += oracle_fail(it, "freshness value not past the last one (a replay)", k, 0);
    }
    if ((!mi->have_fv || last->epoch > mi->fv_epoch) && last->counter > 7u) {
        bad += oracle_fail(it, "an epoch's first frame past its first 8", k, 0);
    }
    mi->have_fv = 1;
    mi->fv_epoch = last->epoch;
    mi->fv_counter = last->counter;
    return bad;
}

/* Checks the node's verdict v against the model's rv (and the model's account of the sequence
 * and freshness), and moves the model on as the node must have moved. */
long oracle_judge(const mrs_node_t *n, mrs_rx_verdict_t v, mrs_rx_verdict_t rv, int k, const ref_t *r, int keyed,
                  long it)
{
    model_in_t *mi;
    unsigned delta;
    int ok;
    long bad = 0;
    if (k >= 0 && k < N_IN && v != MRS_RX_ACCEPTED && v != MRS_RX_IGNORED && n->in[k].bad_cause != CAUSE[v]) {
        bad += oracle_fail(it, "the input's cause bit is not its rejection's", k, (int)v);
    }
    if (rv != MRS_RX_ACCEPTED || v == MRS_RX_IGNORED) {
        return bad + (v != rv ? oracle_fail(it, "verdict is not the first failing check", k, (int)v) : 0);
    }
    if (k == K_SYNC) {
        if (v == MRS_RX_ACCEPTED) {
            const uint8_t none[1] = {0u}; /* a sync's MAC covers frame ID || epoch */
            if (ref_mac(IDS[K_SYNC], none, 0u, r->epoch, mrs_messages[MRS_MSG_SYNC].mac_bits) != r->mac ||
                (model.have_epoch && r->epoch <= model.epoch)) {
                bad += oracle_fail(it, "accepted a forged or old sync", k, (int)v);
            }
            model.prev = model.epoch;
            model.have_prev = model.have_epoch;
            model.epoch = r->epoch;
            model.have_epoch = 1;
        } else if (v != MRS_RX_MAC) {
            bad += oracle_fail(it, "sync verdict", k, (int)v);
        }
        return bad;
    }
    if (v == MRS_RX_MAC) {
        return bad + (!keyed ? oracle_fail(it, "MAC verdict without a key", k, (int)v) : 0);
    }
    if (v != MRS_RX_ACCEPTED && v != MRS_RX_REPEATED && v != MRS_RX_WRONG_SEQUENCE) {
        return bad + oracle_fail(it, "verdict is not the first failing check", k, (int)v);
    }
    if (keyed) {
        bad += fv_sound(n, k, r, it); /* the MAC passed before the sequence check */
    }
    mi = &model.in[k];
    delta = (r->counter + ALIVE_MOD - mi->alive) % ALIVE_MOD;
    if (!mi->have_alive) {
        ok = v == MRS_RX_ACCEPTED;
    } else {
        ok = v == MRS_RX_ACCEPTED ? (delta >= 1u && delta <= MAX_DELTA)
                                  : (v == MRS_RX_REPEATED ? delta == 0u : delta > MAX_DELTA);
    }
    if (!ok) {
        bad += oracle_fail(it, "alive-counter verdict against the sequence", k, (int)v);
    }
    if (v != MRS_RX_REPEATED) {
        mi->alive = r->counter;
        mi->have_alive = 1;
    }
    return bad;
}

