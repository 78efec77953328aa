/*
 * E2E protection of the mrsteer frames, C99 port of dbc/__init__.py (AUTOSAR E2E profile 1,
 * variant 1A, as AUTOSAR R4 E2E_P01Protect with E2E_P01_DATAID_BOTH computes it): the CRC is
 * Crc_CalculateCRC8 chained from start value 0xFF with IsFirstCall = FALSE over the data ID
 * (low byte, high byte) and every payload byte except the CRC byte, then XORed with 0xFF (the
 * bare polynomial 0x1D with register start 0x00 and no final XOR); a 4-bit alive counter 0..14.
 * The receiver's counter check differs from E2E_P01Check where docs/can-runtime.md says so.
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

/* AUTOSAR Crc_CalculateCRC8 (CRC-8/SAE-J1850, poly 0x1D): with is_first_call the register
 * starts at 0xFF and start_value is ignored; otherwise start_value is the previous call's result
 * and the register resumes at start_value ^ 0xFF. The result is the register XOR 0xFF. */
uint8_t mrs_crc_calculate_crc8(const uint8_t *data, size_t len, uint8_t start_value, int is_first_call);

/* CRC-8/SAE-J1850: poly 0x1D, init 0xFF, final XOR 0xFF (check value 0x4B for "123456789"). */
uint8_t mrs_crc8_sae_j1850(const uint8_t *data, size_t len);

/* The E2E_P01 CRC (data ID mode BOTH) of a frame whose CRC sits in byte crc_byte. */
uint8_t mrs_e2e_crc(uint16_t data_id, const uint8_t *payload, size_t len, size_t crc_byte);

/* Sender: the next alive counter (0..14, wrapping). */
uint8_t mrs_e2e_next_counter(uint8_t counter);

/* Receiver: counter-sequence check (accepted: OK, OK_SOME_LOST, INITIAL). */
void mrs_e2e_receiver_init(mrs_e2e_receiver_t *r, uint8_t max_delta);
mrs_e2e_status_t mrs_e2e_check_counter(mrs_e2e_receiver_t *r, uint8_t counter);

#endif
