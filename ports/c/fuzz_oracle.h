/* The fuzzer's model of what the C node's receive chain must do (fuzz_rx.c), written apart from
 * the code under test: frame IDs and lengths from the cantools codec's macros, the E2E CRC as one
 * plain CRC-8 (poly 0x1D, register 0, no final XOR) over data ID low, high and the payload
 * without its CRC byte, the ranges from the cantools codec's *_is_in_range, the MACs from
 * OpenSSL's CMAC over frame ID || payload with CRC and MAC zeroed (repacked by the cantools
 * codec) || FV. Only the data IDs, CRC byte positions and MAC lengths are read from the node's
 * contract table. oracle_judge checks one verdict against the model and moves the model on. */
#ifndef FUZZ_ORACLE_H
#define FUZZ_ORACLE_H

#include <stddef.h>
#include <stdint.h>

#include "mrs_node_core.h"

#define N_IN 4 /* the node's inputs, in mrs_node_t.in's order */
#define K_SYNC 4 /* MRS_SecOCSync's index in the tables below */
#define MAX_DELTA 3u
#define ALIVE_MOD 15u

extern const uint32_t IDS[5];
extern const size_t LENS[5];
extern const int MSGS[5]; /* each one's MRS_MSG_* */

typedef struct {
    unsigned counter, fv_epoch, fv_counter;
    uint64_t mac, epoch;
    int in_range;
    uint8_t zeroed[8]; /* the payload with CRC and MAC zero, repacked by the cantools codec */
} ref_t;

uint8_t ref_crc(uint16_t data_id, const uint8_t *d, size_t len, size_t crc_byte);
/* Unpacks message k (index in IDS) with the cantools codec: 0, or -1 if it cannot. */
int ref_decode(int k, const uint8_t *d, size_t len, ref_t *r);
int ref_key(const uint8_t key[16]);
void ref_free(void);
/* The leading `bits` of the CMAC of frame ID (2 bytes) || body || tail (8 bytes), big-endian. */
uint64_t ref_mac(uint32_t id, const uint8_t *body, size_t len, uint64_t tail, unsigned bits);
/* The first check of the chain the frame fails before MAC and sequence (ACCEPTED: none); *slot
 * gets its index in IDS, -1 if it is not one of the node's. */
mrs_rx_verdict_t ref_verdict(int keyed, uint32_t id, uint8_t flags, const uint8_t *d, size_t len, int *slot,
                             ref_t *r);
/* Violations (0 or more) of the node's verdict v on a frame the model gives rv, slot k and r. */
long oracle_judge(const mrs_node_t *n, mrs_rx_verdict_t v, mrs_rx_verdict_t rv, int k, const ref_t *r, int keyed,
                  long it);
/* Prints what was violated at iteration it; 1. */
long oracle_fail(long it, const char *what, int k, int v);

#endif
