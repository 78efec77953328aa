/* The controller's receive check (see mrs_rx.h): C99 port of mrsteer_dbc.link.RxLink.accept. */
#include "mrs_rx.h"

#include <stdbool.h>

#include "mrs_dbc_e2e.h"
#include "mrsteer.h"

#define MRS_RX_COUNTER_INVALID 15u

/* Length, CRC and alive-counter value of an E2E frame (Contract.decode's first checks). */
static mrs_rx_verdict_t check_frame(const uint8_t *data, size_t len, size_t want_len, uint16_t data_id,
                                    size_t crc_byte)
{
    mrs_rx_verdict_t v = MRS_RX_ACCEPTED;
    if (len != want_len) {
        v = MRS_RX_LENGTH;
    } else if (data[crc_byte] != mrs_e2e_crc(data_id, data, len, crc_byte)) {
        v = MRS_RX_CRC;
    } else {
        v = MRS_RX_ACCEPTED;
    }
    return v;
}

/* Unpack and range-check one sensor message; its measurement into *value, counter into *counter. */
static mrs_rx_verdict_t decode_steer(const uint8_t *data, size_t len, double *value, uint8_t *counter)
{
    struct mrsteer_mrs_driver_steer_t m;
    mrs_rx_verdict_t v = MRS_RX_RANGE;
    if (mrsteer_mrs_driver_steer_unpack(&m, data, len) == 0) {
        *counter = m.driver_steer_counter;
        if (m.driver_steer_counter == MRS_RX_COUNTER_INVALID) {
            v = MRS_RX_COUNTER_VALUE;
        } else if (mrsteer_mrs_driver_steer_driver_steer_counter_is_in_range(m.driver_steer_counter) &&
                   mrsteer_mrs_driver_steer_driver_steer_fv_epoch_is_in_range(m.driver_steer_fv_epoch) &&
                   mrsteer_mrs_driver_steer_driver_steer_fv_counter_is_in_range(m.driver_steer_fv_counter) &&
                   mrsteer_mrs_driver_steer_driver_steer_angle_is_in_range(m.driver_steer_angle) &&
                   mrsteer_mrs_driver_steer_driver_steer_mac_is_in_range(m.driver_steer_mac)) {
            *value = mrsteer_mrs_driver_steer_driver_steer_angle_decode(m.driver_steer_angle);
            v = MRS_RX_ACCEPTED;
        } else {
            v = MRS_RX_RANGE;
        }
    }
    return v;
}

static mrs_rx_verdict_t decode_yaw(const uint8_t *data, size_t len, double *value, uint8_t *counter)
{
    struct mrsteer_mrs_yaw_rate_t m;
    mrs_rx_verdict_t v = MRS_RX_RANGE;
    if (mrsteer_mrs_yaw_rate_unpack(&m, data, len) == 0) {
        *counter = m.yaw_rate_counter;
        if (m.yaw_rate_counter == MRS_RX_COUNTER_INVALID) {
            v = MRS_RX_COUNTER_VALUE;
        } else if (mrsteer_mrs_yaw_rate_yaw_rate_counter_is_in_range(m.yaw_rate_counter) &&
                   mrsteer_mrs_yaw_rate_yaw_rate_fv_epoch_is_in_range(m.yaw_rate_fv_epoch) &&
                   mrsteer_mrs_yaw_rate_yaw_rate_fv_counter_is_in_range(m.yaw_rate_fv_counter) &&
                   mrsteer_mrs_yaw_rate_yaw_rate_yaw_rate_is_in_range(m.yaw_rate_yaw_rate) &&
                   mrsteer_mrs_yaw_rate_yaw_rate_mac_is_in_range(m.yaw_rate_mac)) {
            *value = mrsteer_mrs_yaw_rate_yaw_rate_yaw_rate_decode(m.yaw_rate_yaw_rate);
            v = MRS_RX_ACCEPTED;
        } else {
            v = MRS_RX_RANGE;
        }
    }
    return v;
}

static mrs_rx_verdict_t decode_speed(const uint8_t *data, size_t len, double *value, uint8_t *counter)
{
    struct mrsteer_mrs_vehicle_speed_t m;
    mrs_rx_verdict_t v = MRS_RX_RANGE;
    if (mrsteer_mrs_vehicle_speed_unpack(&m, data, len) == 0) {
        *counter = m.vehicle_speed_counter;
        if (m.vehicle_speed_counter == MRS_RX_COUNTER_INVALID) {
            v = MRS_RX_COUNTER_VALUE;
        } else if (mrsteer_mrs_vehicle_speed_vehicle_speed_counter_is_in_range(m.vehicle_speed_counter) &&
                   mrsteer_mrs_vehicle_speed_vehicle_speed_fv_epoch_is_in_range(m.vehicle_speed_fv_epoch) &&
                   mrsteer_mrs_vehicle_speed_vehicle_speed_fv_counter_is_in_range(m.vehicle_speed_fv_counter) &&
                   mrsteer_mrs_vehicle_speed_vehicle_speed_speed_is_in_range(m.vehicle_speed_speed) &&
                   mrsteer_mrs_vehicle_speed_vehicle_speed_mac_is_in_range(m.vehicle_speed_mac)) {
            *value = mrsteer_mrs_vehicle_speed_vehicle_speed_speed_decode(m.vehicle_speed_speed);
            v = MRS_RX_ACCEPTED;
        } else {
            v = MRS_RX_RANGE;
        }
    }
    return v;
}

static mrs_rx_verdict_t sequence(mrs_e2e_receiver_t *r, uint8_t counter, mrs_e2e_status_t *status)
{
    mrs_rx_verdict_t v = MRS_RX_ACCEPTED;
    *status = mrs_e2e_check_counter(r, counter);
    if (*status == MRS_E2E_REPEATED) {
        v = MRS_RX_REPEATED;
    } else if (*status == MRS_E2E_WRONG_SEQUENCE) {
        v = MRS_RX_WRONG_SEQUENCE;
    } else {
        v = MRS_RX_ACCEPTED;
    }
    return v;
}

void mrs_rx_init(mrs_rx_t *rx, uint8_t max_delta, mrs_rx_mac_fn mac, void *mac_ctx)
{
    size_t i;
    for (i = 0u; i < (size_t)MRS_RX_N_INPUTS; ++i) {
        mrs_e2e_receiver_init(&rx->counters[i], max_delta);
    }
    rx->mac = mac;
    rx->mac_ctx = mac_ctx;
}

mrs_rx_verdict_t mrs_rx_accept(mrs_rx_t *rx, uint32_t can_id, const uint8_t *data, size_t len,
                               mrs_rx_frame_t *out)
{
    const uint32_t flags = MRS_RX_CAN_EFF_FLAG | MRS_RX_CAN_RTR_FLAG | MRS_RX_CAN_ERR_FLAG;
    mrs_rx_verdict_t v = MRS_RX_IGNORED;
    mrs_rx_input_t input = MRS_RX_STEER;
    double value = 0.0;
    uint8_t counter = 0u;
    mrs_e2e_status_t status = MRS_E2E_OK;

    if ((can_id & flags) != 0u) {
        v = MRS_RX_IGNORED;
    } else if (can_id == MRSTEER_MRS_DRIVER_STEER_FRAME_ID) {
        input = MRS_RX_STEER;
        v = check_frame(data, len, MRSTEER_MRS_DRIVER_STEER_LENGTH, MRS_DRIVER_STEER_E2E_DATA_ID,
                        MRS_DRIVER_STEER_E2E_CRC_BYTE);
        if (v == MRS_RX_ACCEPTED) {
            v = decode_steer(data, len, &value, &counter);
        }
    } else if (can_id == MRSTEER_MRS_YAW_RATE_FRAME_ID) {
        input = MRS_RX_YAW;
        v = check_frame(data, len, MRSTEER_MRS_YAW_RATE_LENGTH, MRS_YAW_RATE_E2E_DATA_ID, MRS_YAW_RATE_E2E_CRC_BYTE);
        if (v == MRS_RX_ACCEPTED) {
            v = decode_yaw(data, len, &value, &counter);
        }
    } else if (can_id == MRSTEER_MRS_VEHICLE_SPEED_FRAME_ID) {
        input = MRS_RX_SPEED;
        v = check_frame(data, len, MRSTEER_MRS_VEHICLE_SPEED_LENGTH, MRS_VEHICLE_SPEED_E2E_DATA_ID,
                        MRS_VEHICLE_SPEED_E2E_CRC_BYTE);
        if (v == MRS_RX_ACCEPTED) {
            v = decode_speed(data, len, &value, &counter);
        }
    } else {
        v = MRS_RX_IGNORED;
    }
    /* Authenticate before the counter check: a forged frame must not advance the sequence. */
    if ((v == MRS_RX_ACCEPTED) && (rx->mac != NULL) && (rx->mac(rx->mac_ctx, can_id, data, len) == 0)) {
        v = MRS_RX_MAC;
    }
    if (v == MRS_RX_ACCEPTED) {
        v = sequence(&rx->counters[input], counter, &status);
    }
    if (v == MRS_RX_ACCEPTED) {
        out->input = input;
        out->value = value;
        out->counter = counter;
        out->status = status;
    }
    return v;
}

uint8_t mrs_rx_cause(mrs_rx_verdict_t verdict)
{
    uint8_t cause = 0u;
    switch (verdict) {
    case MRS_RX_LENGTH:
    case MRS_RX_CRC:
    case MRS_RX_COUNTER_VALUE:
    case MRS_RX_REPEATED:
    case MRS_RX_WRONG_SEQUENCE:
        cause = (uint8_t)MRS_RX_CAUSE_E2E;
        break;
    case MRS_RX_RANGE:
        cause = (uint8_t)MRS_RX_CAUSE_RANGE;
        break;
    case MRS_RX_MAC:
        cause = (uint8_t)MRS_RX_CAUSE_AUTH;
        break;
    default:
        cause = 0u;
        break;
    }
    return cause;
}
