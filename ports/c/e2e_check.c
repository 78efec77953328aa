/* Reads "MAX_DELTA" then one alive counter per line; prints the receiver's verdict for each
 * (mrs_e2e_check_counter), and the sender's next counter after it, as two numbers per line. */
#include <stdio.h>

#include "mrs_e2e.h"

int main(void)
{
    mrs_e2e_receiver_t r;
    unsigned max_delta, counter;
    if (scanf("%u", &max_delta) != 1) {
        return 2;
    }
    mrs_e2e_receiver_init(&r, (uint8_t)max_delta);
    while (scanf("%u", &counter) == 1) {
        const mrs_e2e_status_t st = mrs_e2e_check_counter(&r, (uint8_t)counter);
        printf("%d %u\n", (int)st, (unsigned)mrs_e2e_next_counter((uint8_t)counter));
    }
    return 0;
}
