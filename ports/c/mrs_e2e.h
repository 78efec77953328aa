/*
 * E2E protection of the mrsteer frames, C99 port of dbc/__init__.py (AUTOSAR E2E profile 1
 * style, variant 1A): CRC-8/SAE-J1850 over the data ID (low byte, high byte) and every payload
 * byte except the CRC byte; a 4-bit alive counter 0..14.
 */
#ifndef MRS_E2E_H
#define MRS_E2E_H

#include <stddef.h>
#include <stdint.h>

#define MRS_E2E_COUNTER_MODULO 15u

typedef enum {
    MRS_E2E_OK = 0,
    MRS_E2E_OK_SOME_LOST = 1,
    MRS_E2E_INITIAL = 2,
    MRS_E2E_REPEATED = 3,
    MRS_E2E_WRONG_SEQUENCE = 4
} mrs_e2e_status_t;

typedef struct {
    uint8_t last;
    uint8_t have_last;
    uint8_t max_delta;
} mrs_e2e_receiver_t;

/* CRC-8/SAE-J1850: poly 0x1D, init 0xFF, final XOR 0xFF (check value 0x4B for "123456789"). */
uint8_t mrs_crc8_sae_j1850(const uint8_t *data, size_t len);

/* The E2E CRC of a frame whose CRC sits in byte crc_byte. */
uint8_t mrs_e2e_crc(uint16_t data_id, const uint8_t *payload, size_t len, size_t crc_byte);

/* Sender: the next alive counter (0..14, wrapping). */
uint8_t mrs_e2e_next_counter(uint8_t counter);

/* Receiver: counter-sequence check (accepted: OK, OK_SOME_LOST, INITIAL). */
void mrs_e2e_receiver_init(mrs_e2e_receiver_t *r, uint8_t max_delta);
mrs_e2e_status_t mrs_e2e_check_counter(mrs_e2e_receiver_t *r, uint8_t counter);

#endif
