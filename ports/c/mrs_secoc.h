/*
 * SecOC of the C controller node, C99 port of mrsteer_dbc/secoc (docs/faults.md has the design,
 * docs/porting.md the framing): the truncated AES-128-CMAC (OpenSSL libcrypto, EVP_MAC), the
 * key file, the command signer that takes its freshness epochs from authentic MRS_SecOCSync
 * frames, and the sensor-frame verifier.
 *
 * Freshness value FV = epoch << 24 | counter (64 bits). Authenticated data, big-endian:
 *   command and sensor frames: frame ID (2 bytes) || payload with CRC byte and MAC bits zero || FV (8)
 *   sync: frame ID (2 bytes) || epoch (8)
 * The MAC is the leading bits of the 128-bit CMAC.
 */
#ifndef MRS_SECOC_H
#define MRS_SECOC_H

#include <stddef.h>
#include <stdint.h>

#include "mrs_contract.h"

#define MRS_SECOC_KEY_BYTES 16u
#define MRS_SECOC_COUNTER_BITS 24u
#define MRS_SECOC_SENSOR_MAX_ADVANCE 15u
#define MRS_SECOC_KEY_ENV "MRSTEER_SECOC_KEY"

typedef struct mrs_cmac mrs_cmac_t; /* an AES-128-CMAC keyed once */

/* The key from a file (32 hex digits, whitespace around them allowed) or, with path NULL, from
 * $MRSTEER_SECOC_KEY; 0, or -1 with the reason in err (worded as mrsteer_dbc.secoc.load_key). */
int mrs_secoc_load_key(const char *path, uint8_t key[MRS_SECOC_KEY_BYTES], char *err, size_t err_len);

mrs_cmac_t *mrs_cmac_new(const uint8_t key[MRS_SECOC_KEY_BYTES]);
void mrs_cmac_free(mrs_cmac_t *c);
/* The leading bits (1..64) of the CMAC of data. */
uint64_t mrs_cmac_trunc(mrs_cmac_t *c, const uint8_t *data, size_t len, unsigned bits);

/* The authenticator of one frame: CMAC over frame ID || zeroed || FV, leading bits. */
uint64_t mrs_frame_mac(mrs_cmac_t *c, uint32_t frame_id, const uint8_t *zeroed, size_t len, uint64_t fv,
                       unsigned bits);

/* Controller side of the command (CommandSigner). */
typedef struct {
    int have_epoch;
    uint64_t epoch;
    uint32_t counter;
} mrs_signer_t;

int mrs_signer_synced(const mrs_signer_t *s);
/* A sync frame's check: adopt an authentic epoch newer than ours (1), else 0. */
int mrs_signer_accept_sync(mrs_signer_t *s, mrs_cmac_t *c, const mrs_msg_t *sync, const double *phys);
/* Sets the SecOC fields of a command's physical values for the next freshness value when synced
 * (MAC 0 still); *fv is that FV. 1 if the frame is to be authenticated, 0 if it goes unsigned. */
int mrs_signer_next(mrs_signer_t *s, const mrs_msg_t *cmd, double *phys, uint64_t *fv);

/* Controller side of the sensor frames (SensorVerifier). */
typedef struct {
    int have;
    uint64_t epoch;
    uint32_t counter;
    unsigned alive;
} mrs_sensor_last_t;

typedef struct {
    int have_current, have_previous;
    uint64_t current, previous;
    mrs_sensor_last_t last[MRS_N_MESSAGES];
} mrs_sensor_verifier_t;

void mrs_sensor_adopt(mrs_sensor_verifier_t *v, uint64_t epoch);
/* 1 if the sensor frame (which passed length, CRC and range) verifies for a freshness value
 * 1..MRS_SECOC_SENSOR_MAX_ADVANCE past its message's last accepted one (which it then becomes). */
int mrs_sensor_verify(mrs_sensor_verifier_t *v, mrs_cmac_t *c, int msg_index, const uint8_t *data,
                      const double *phys);

#endif
