/* Reads "MAX_DELTA" then one alive counter per line; prints the receiver's verdict for each
 * (mrs_e2e_check_counter), and the sender's next counter after it, as two numbers per line.
 * Or reads "crc" then lines "DATA_ID CRC_BYTE HEX" (decimal, decimal, frame bytes in hex) and
 * prints the frame's E2E CRC (mrs_e2e_crc) in decimal, one per line. */
#include <stdio.h>
#include <string.h>

#include "mrs_e2e.h"

static int crc_mode(void)
{
    unsigned data_id, crc_byte;
    char hex[2u * 64u + 1u];
    while (scanf("%u %u %128s", &data_id, &crc_byte, hex) == 3) {
        uint8_t data[64];
        size_t i, len = strlen(hex) / 2u;
        for (i = 0u; i < len; ++i) {
            unsigned b;
            if (sscanf(hex + 2u * i, "%2x", &b) != 1) {
                return 2;
            }
            data[i] = (uint8_t)b;
        }
        printf("%u\n", (unsigned)mrs_e2e_crc((uint16_t)data_id, data, len, (size_t)crc_byte));
    }
    return 0;
}

int main(void)
{
    mrs_e2e_receiver_t r;
    unsigned max_delta, counter;
    char first[16];
    if (scanf("%15s", first) != 1) {
        return 2;
    }
    if (strcmp(first, "crc") == 0) {
        return crc_mode();
    }
    if (sscanf(first, "%u", &max_delta) != 1) {
        return 2;
    }
    mrs_e2e_receiver_init(&r, (uint8_t)max_delta);
    while (scanf("%u", &counter) == 1) {
        const mrs_e2e_status_t st = mrs_e2e_check_counter(&r, (uint8_t)counter);
        printf("%d %u\n", (int)st, (unsigned)mrs_e2e_next_counter((uint8_t)counter));
    }
    return 0;
}
