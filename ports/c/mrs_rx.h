/*
 * The controller's receive check, C99 port of mrsteer_dbc.link.RxLink.accept for its sensor
 * messages (MRS_DriverSteer, MRS_YawRate, MRS_VehicleSpeed): one frame in, a verdict out, in
 * the same order as the Python link:
 *
 *   not one of these messages (other ID, extended, remote or error frame): IGNORED;
 *   length (exactly the DBC's) -> E2E CRC -> alive counter value 15 -> every signal's DBC range
 *   (the cantools-generated unpack and *_is_in_range) -> SecOC MAC (the caller's hook, when
 *   given) -> alive-counter sequence (mrs_e2e_check_counter), last.
 *
 * The MAC is checked before the counter so that a forged frame cannot advance the sequence; the
 * MAC itself (AES-CMAC, freshness) is the node's: pass a mrs_rx_mac_fn to mrs_rx_init, or NULL
 * to accept every frame's MAC field as it is (authentication off).
 *
 * Frame IDs, lengths and layouts come from the cantools-generated codec (mrsteer.h), the E2E
 * data IDs and CRC byte positions from mrs_dbc_e2e.h (gen_e2e_ids.py): no bit position here.
 */
#ifndef MRS_RX_H
#define MRS_RX_H

#include <stddef.h>
#include <stdint.h>

#include "mrs_e2e.h"

/* SocketCAN's flag bits in a can_id (linux/can.h), so that a raw can_id can be passed as read. */
#define MRS_RX_CAN_EFF_FLAG 0x80000000u
#define MRS_RX_CAN_RTR_FLAG 0x40000000u
#define MRS_RX_CAN_ERR_FLAG 0x20000000u

/* CtrlStatus_Cause bits a rejection stands for (dbc/names.py: CAUSE_E2E, CAUSE_RANGE, CAUSE_AUTH). */
#define MRS_RX_CAUSE_E2E 0x08u
#define MRS_RX_CAUSE_RANGE 0x10u
#define MRS_RX_CAUSE_AUTH 0x40u

typedef enum {
    MRS_RX_STEER = 0,
    MRS_RX_YAW = 1,
    MRS_RX_SPEED = 2,
    MRS_RX_N_INPUTS = 3
} mrs_rx_input_t;

/* Rejected.* of dbc/link.py, in the same order of checks. */
typedef enum {
    MRS_RX_ACCEPTED = 0,
    MRS_RX_IGNORED = 1,
    MRS_RX_LENGTH = 2,
    MRS_RX_CRC = 3,
    MRS_RX_COUNTER_VALUE = 4,
    MRS_RX_RANGE = 5,
    MRS_RX_MAC = 6,
    MRS_RX_REPEATED = 7,
    MRS_RX_WRONG_SEQUENCE = 8
} mrs_rx_verdict_t;

/* Returns nonzero when the frame's MAC and freshness verify (the frame has passed length, CRC
 * and range; frame_id has no flag bits). */
typedef int (*mrs_rx_mac_fn)(void *ctx, uint32_t frame_id, const uint8_t *data, size_t len);

typedef struct {
    mrs_e2e_receiver_t counters[MRS_RX_N_INPUTS];
    mrs_rx_mac_fn mac;
    void *mac_ctx;
} mrs_rx_t;

/* An accepted frame: which input, its measurement (physical units of the DBC), its alive
 * counter and how the counter advanced (OK, OK_SOME_LOST or INITIAL). */
typedef struct {
    mrs_rx_input_t input;
    double value;
    uint8_t counter;
    mrs_e2e_status_t status;
} mrs_rx_frame_t;

void mrs_rx_init(mrs_rx_t *rx, uint8_t max_delta, mrs_rx_mac_fn mac, void *mac_ctx);

/* The verdict on one frame; *out is written only when ACCEPTED. */
mrs_rx_verdict_t mrs_rx_accept(mrs_rx_t *rx, uint32_t can_id, const uint8_t *data, size_t len,
                               mrs_rx_frame_t *out);

/* The CtrlStatus_Cause bit of a verdict (0 for ACCEPTED and IGNORED). */
uint8_t mrs_rx_cause(mrs_rx_verdict_t verdict);

#endif
