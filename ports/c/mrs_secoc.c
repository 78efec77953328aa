/* SecOC of the C controller node: see mrs_secoc.h. AES-CMAC is OpenSSL's (EVP_MAC "CMAC"). */
#include "mrs_secoc.h"

#include <ctype.h>
#include <errno.h>
#include <openssl/core_names.h>
#include <openssl/evp.h>
#include <openssl/params.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

struct mrs_cmac {
    EVP_MAC *mac;
    EVP_MAC_CTX *base; /* keyed once; duplicated per message */
};

static int hex_digit(int ch)
{
    if (ch >= '0' && ch <= '9') {
        return ch - '0';
    }
    ch = tolower(ch);
    return (ch >= 'a' && ch <= 'f') ? ch - 'a' + 10 : -1;
}

int mrs_secoc_load_key(const char *path, uint8_t key[MRS_SECOC_KEY_BYTES], char *err, size_t err_len)
{
    char text[256], source[300];
    size_t n = 0u, i, start = 0u;
    if (path != NULL) {
        FILE *f = fopen(path, "r");
        if (f == NULL) {
            snprintf(err, err_len, "cannot read the SecOC key file %s: %s", path, strerror(errno));
            return -1;
        }
        n = fread(text, 1u, sizeof text - 1u, f);
        fclose(f);
        snprintf(source, sizeof source, "key file %s", path);
    } else {
        const char *env = getenv(MRS_SECOC_KEY_ENV);
        n = env != NULL ? strlen(env) : 0u;
        if (n >= sizeof text) {
            n = sizeof text - 1u;
        }
        memcpy(text, env != NULL ? env : "", n);
        snprintf(source, sizeof source, "$%s", MRS_SECOC_KEY_ENV);
    }
    text[n] = '\0';
    while (n > 0u && isspace((unsigned char)text[n - 1u])) {
        text[--n] = '\0';
    }
    while (start < n && isspace((unsigned char)text[start])) {
        ++start;
    }
    if (path == NULL && start == n) {
        snprintf(err, err_len, "no SecOC key: give --secoc-key FILE or set %s to 32 hex digits", MRS_SECOC_KEY_ENV);
        return -1;
    }
    for (i = start; i < n; ++i) {
        if (hex_digit((unsigned char)text[i]) < 0) {
            snprintf(err, err_len, "the SecOC key in %s is not hexadecimal", source);
            return -1;
        }
    }
    if ((n - start) % 2u != 0u) {
        snprintf(err, err_len, "the SecOC key in %s is not hexadecimal", source);
        return -1;
    }
    if ((n - start) != 2u * MRS_SECOC_KEY_BYTES) {
        snprintf(err, err_len, "the SecOC key in %s must be %u bytes (32 hex digits), got %u", source,
                 MRS_SECOC_KEY_BYTES, (unsigned)((n - start) / 2u));
        return -1;
    }
    for (i = 0u; i < MRS_SECOC_KEY_BYTES; ++i) {
        key[i] = (uint8_t)(hex_digit((unsigned char)text[start + 2u * i]) * 16 +
                           hex_digit((unsigned char)text[start + 2u * i + 1u]));
    }
    return 0;
}

mrs_cmac_t *mrs_cmac_new(const uint8_t key[MRS_SECOC_KEY_BYTES])
{
    char cipher[] = "AES-128-CBC";
    OSSL_PARAM params[2];
    mrs_cmac_t *c = calloc(1u, sizeof *c);
    if (c == NULL) {
        return NULL;
    }
    params[0] = OSSL_PARAM_construct_utf8_string(OSSL_MAC_PARAM_CIPHER, cipher, 0u);
    params[1] = OSSL_PARAM_construct_end();
    c->mac = EVP_MAC_fetch(NULL, "CMAC", NULL);
    c->base = c->mac != NULL ? EVP_MAC_CTX_new(c->mac) : NULL;
    if (c->base == NULL || EVP_MAC_init(c->base, key, MRS_SECOC_KEY_BYTES, params) != 1) {
        mrs_cmac_free(c);
        return NULL;
    }
    return c;
}

void mrs_cmac_free(mrs_cmac_t *c)
{
    if (c != NULL) {
        EVP_MAC_CTX_free(c->base);
        EVP_MAC_free(c->mac);
        free(c);
    }
}

uint64_t mrs_cmac_trunc(mrs_cmac_t *c, const uint8_t *data, size_t len, unsigned bits)
{
    uint8_t out[16];
    size_t out_len = 0u;
    uint64_t lead = 0u;
    int i;
    EVP_MAC_CTX *ctx = EVP_MAC_CTX_dup(c->base);
    if (ctx == NULL || EVP_MAC_update(ctx, data, len) != 1 || EVP_MAC_final(ctx, out, &out_len, sizeof out) != 1 ||
        out_len != 16u) {
        /* No MAC: a value no 64-bit-or-shorter field equals after the shift is impossible, so
         * fail closed by returning the complement of nothing known; callers compare and reject. */
        EVP_MAC_CTX_free(ctx);
        return ~(uint64_t)0;
    }
    EVP_MAC_CTX_free(ctx);
    for (i = 0; i < 8; ++i) {
        lead = (lead << 8) | out[i];
    }
    return bits >= 64u ? lead : lead >> (64u - bits);
}

static void put_be(uint8_t *p, uint64_t x, unsigned n)
{
    unsigned i;
    for (i = 0u; i < n; ++i) {
        p[i] = (uint8_t)(x >> (8u * (n - 1u - i)));
    }
}

uint64_t mrs_frame_mac(mrs_cmac_t *c, uint32_t frame_id, const uint8_t *zeroed, size_t len, uint64_t fv,
                       unsigned bits)
{
    uint8_t buf[2 + 64 + 8];
    put_be(buf, frame_id, 2u);
    memcpy(buf + 2, zeroed, len);
    put_be(buf + 2 + len, fv, 8u);
    return mrs_cmac_trunc(c, buf, 2u + len + 8u, bits);
}

static uint64_t freshness(uint64_t epoch, uint32_t counter)
{
    return (epoch << MRS_SECOC_COUNTER_BITS) | counter;
}

int mrs_signer_synced(const mrs_signer_t *s)
{
    return s->have_epoch && s->counter < (1u << MRS_SECOC_COUNTER_BITS);
}

int mrs_signer_accept_sync(mrs_signer_t *s, mrs_cmac_t *c, const mrs_msg_t *sync, const double *phys)
{
    uint8_t buf[10];
    const uint64_t epoch = (uint64_t)phys[sync->epoch];
    put_be(buf, sync->frame_id, 2u);
    put_be(buf + 2, epoch, 8u);
    if ((uint64_t)phys[sync->mac] != mrs_cmac_trunc(c, buf, sizeof buf, sync->mac_bits) ||
        (s->have_epoch && epoch <= s->epoch)) {
        return 0;
    }
    s->have_epoch = 1;
    s->epoch = epoch;
    s->counter = 0u;
    return 1;
}

int mrs_signer_next(mrs_signer_t *s, const mrs_msg_t *cmd, double *phys, uint64_t *fv)
{
    if (!mrs_signer_synced(s)) {
        return 0;
    }
    phys[cmd->fv_epoch] = (double)(s->epoch & 1u);
    phys[cmd->fv_counter] = (double)(s->counter & ((1u << cmd->fv_counter_bits) - 1u));
    phys[cmd->mac] = 0.0;
    *fv = freshness(s->epoch, s->counter);
    ++s->counter;
    return 1;
}

void mrs_sensor_adopt(mrs_sensor_verifier_t *v, uint64_t epoch)
{
    if (!v->have_current || epoch > v->current) {
        v->previous = v->current;
        v->have_previous = v->have_current;
        v->current = epoch;
        v->have_current = 1;
    }
}

/* How far the FV counter is past the last accepted one (1..120), from the alive counter's
 * advance (mod 15) and the FV counter's low 3 bits' (mod 8): 8 and 15 are coprime. */
static unsigned counter_advance(int alive_delta, int low_delta)
{
    const int low = ((low_delta % 8) + 8) % 8;
    const int k = (((2 * (alive_delta - low)) % 15) + 15) % 15;
    const int advance = low + 8 * k;
    return advance != 0 ? (unsigned)advance : 120u;
}

int mrs_sensor_verify(mrs_sensor_verifier_t *v, mrs_cmac_t *c, int msg_index, const uint8_t *data,
                      const double *phys)
{
    const mrs_msg_t *m = &mrs_messages[msg_index];
    mrs_sensor_last_t *last = &v->last[msg_index];
    const unsigned alive = (unsigned)phys[m->counter];
    const unsigned low = (unsigned)phys[m->fv_counter];
    const unsigned bit = (unsigned)phys[m->fv_epoch];
    uint8_t zeroed[8];
    uint64_t epoch, counter;
    unsigned advance = 1u, i;
    int have;
    if (v->have_current && (v->current & 1u) == bit) {
        have = 1;
        epoch = v->current;
    } else {
        have = v->have_previous;
        epoch = v->previous;
    }
    if (!have || (last->have && epoch < last->epoch)) {
        return 0;
    }
    if (last->have && epoch == last->epoch) {
        advance = counter_advance((int)alive - (int)last->alive, (int)low - (int)last->counter);
        counter = (uint64_t)last->counter + advance;
    } else {
        counter = low; /* the epoch's first accepted frame must be one of its first 8 */
    }
    if (advance > MRS_SECOC_SENSOR_MAX_ADVANCE || counter >= (1u << MRS_SECOC_COUNTER_BITS)) {
        return 0; /* the window first: a replay is refused before any MAC is computed */
    }
    for (i = 0u; i < m->length; ++i) {
        zeroed[i] = (uint8_t)(data[i] & m->zero_mask[i]);
    }
    if (mrs_frame_mac(c, m->frame_id, zeroed, m->length, freshness(epoch, (uint32_t)counter), m->mac_bits) !=
        (uint64_t)phys[m->mac]) {
        return 0;
    }
    last->have = 1;
    last->epoch = epoch;
    last->counter = (uint32_t)counter;
    last->alive = alive;
    return 1;
}
