/* E2E CRC and alive counter, C99 port of dbc/__init__.py. */
#include "mrs_e2e.h"

uint8_t mrs_crc_calculate_crc8(const uint8_t *data, size_t len, uint8_t start_value, int is_first_call)
{
    uint8_t crc = is_first_call ? 0xFFu : (uint8_t)(start_value ^ 0xFFu);
    size_t i;
    for (i = 0u; i < len; ++i) {
        int bit;
        crc ^= data[i];
        for (bit = 0; bit < 8; ++bit) {
            crc = (uint8_t)((crc & 0x80u) ? (((unsigned)crc << 1) ^ 0x1Du) : ((unsigned)crc << 1));
        }
    }
    return (uint8_t)(crc ^ 0xFFu);
}

uint8_t mrs_crc8_sae_j1850(const uint8_t *data, size_t len)
{
    return mrs_crc_calculate_crc8(data, len, 0xFFu, 1);
}

uint8_t mrs_e2e_crc(uint16_t data_id, const uint8_t *payload, size_t len, size_t crc_byte)
{
    /* E2E_P01Protect, E2E_P01_DATAID_BOTH: chain from start value 0xFF, never a first call. */
    const uint8_t id[2] = {(uint8_t)(data_id & 0xFFu), (uint8_t)(data_id >> 8)};
    uint8_t crc = mrs_crc_calculate_crc8(&id[0], 1u, 0xFFu, 0);
    crc = mrs_crc_calculate_crc8(&id[1], 1u, crc, 0);
    if (crc_byte > len) {
        crc_byte = len;
    }
    crc = mrs_crc_calculate_crc8(payload, crc_byte, crc, 0);
    if (crc_byte < len) {
        crc = mrs_crc_calculate_crc8(payload + crc_byte + 1u, len - crc_byte - 1u, crc, 0);
    }
    return (uint8_t)(crc ^ 0xFFu);
}

uint8_t mrs_e2e_next_counter(uint8_t counter)
{
    return (uint8_t)((counter + 1u) % MRS_E2E_COUNTER_MODULO);
}

void mrs_e2e_receiver_init(mrs_e2e_receiver_t *r, uint8_t max_delta)
{
    r->last = 0u;
    r->have_last = 0u;
    r->max_delta = max_delta;
}

mrs_e2e_status_t mrs_e2e_check_counter(mrs_e2e_receiver_t *r, uint8_t counter)
{
    uint8_t delta;
    if (!r->have_last) {
        r->last = counter;
        r->have_last = 1u;
        return MRS_E2E_INITIAL;
    }
    delta = (uint8_t)((counter + MRS_E2E_COUNTER_MODULO - r->last) % MRS_E2E_COUNTER_MODULO);
    if (delta == 0u) {
        return MRS_E2E_REPEATED;
    }
    /* Re-synchronise on the new value either way: one bad jump costs one frame. */
    r->last = counter;
    if (delta == 1u) {
        return MRS_E2E_OK;
    }
    return (delta <= r->max_delta) ? MRS_E2E_OK_SOME_LOST : MRS_E2E_WRONG_SEQUENCE;
}
