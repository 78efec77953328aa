/* E2E CRC and alive counter, C99 port of dbc/__init__.py. */
#include "mrs_e2e.h"

uint8_t mrs_crc8_sae_j1850(const uint8_t *data, size_t len)
{
    uint8_t crc = 0xFFu;
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

uint8_t mrs_e2e_crc(uint16_t data_id, const uint8_t *payload, size_t len, size_t crc_byte)
{
    uint8_t buf[2u + 64u];
    size_t i, n = 0u;
    if (len > 64u) {
        return 0u;
    }
    buf[n++] = (uint8_t)(data_id & 0xFFu);
    buf[n++] = (uint8_t)(data_id >> 8);
    for (i = 0u; i < len; ++i) {
        if (i != crc_byte) {
            buf[n++] = payload[i];
        }
    }
    return mrs_crc8_sae_j1850(buf, n);
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
