/* Drives the C node's receive chain and SecOC paths (tests/test_c_node.py feeds it the golden
 * vectors tests/vectors/secoc_*.csv, and random and mutated frames). One command per line on stdin, one answer per line on stdout:
 *   key HEX32                                   the node is set up keyed with this key: "ok"
 *   plain                                       the node is set up without SecOC: "ok"
 *   rx HEX                                      a received frame (sync or sensor) through the
 *                                               node's whole receive chain: "1" accepted, "0" refused
 *   cmd EPOCH FV_COUNTER ALIVE STATE ANGLE MEAS the command frame the node builds with its signer
 *                                               at (EPOCH, FV_COUNTER) and alive counter ALIVE: its hex
 *   ctl                                         one control period (mrs_node_control): the frames it
 *                                               sends, "ID#HEX" (ID in hex) separated by spaces */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "mrs_contract.h"
#include "mrs_node_core.h"

static mrs_node_t node;
static mrs_bus_t bus; /* records nothing: ctl prints what the node sends */
static char sent[256];

static int print_send(mrs_bus_t *b, uint32_t id, const uint8_t *data, uint8_t len)
{
    size_t at = strlen(sent);
    uint8_t i;
    (void)b;
    at += (size_t)snprintf(sent + at, sizeof sent - at, "%s%03X#", at > 0u ? " " : "", (unsigned)id);
    for (i = 0u; i < len && at + 3u < sizeof sent; ++i) {
        at += (size_t)snprintf(sent + at, sizeof sent - at, "%02X", data[i]);
    }
    return 0;
}

static size_t from_hex(const char *hex, uint8_t *out, size_t max)
{
    size_t n = 0u;
    while (n < max && hex[2u * n] != '\0' && hex[2u * n + 1u] != '\0') {
        unsigned b;
        if (sscanf(hex + 2u * n, "%2x", &b) != 1) {
            break;
        }
        out[n++] = (uint8_t)b;
    }
    return n;
}

static int on_rx(const char *id_hex, const char *hex)
{
    mrs_frame_t f;
    const uint64_t before = node.stats.rx_rejected + node.stats.syncs_rejected;
    memset(&f, 0, sizeof f);
    f.id = (uint32_t)strtoul(id_hex, NULL, 16);
    f.len = (uint8_t)from_hex(hex, f.data, 8u);
    mrs_node_receive(&node, &f);
    return node.stats.rx_rejected + node.stats.syncs_rejected == before;
}

int main(void)
{
    char line[512], word[16], a[160], b[160];
    mrs_node_config_t cfg;
    uint8_t key[16];
    char err[256];
    memset(&cfg, 0, sizeof cfg);
    cfg.rate_hz = 500.0;
    cfg.timeout_cycles = 10;
    cfg.e2e_fail_max = 3;
    cfg.max_counter_delta = 3;
    mrs_default_config(&cfg.controller);
    bus.send = print_send;
    while (fgets(line, sizeof line, stdin) != NULL) {
        if (sscanf(line, "%15s", word) != 1) {
            continue;
        }
        if (strcmp(word, "key") == 0 && sscanf(line, "%*s %159s", a) == 1 && from_hex(a, key, 16u) == 16u) {
            cfg.secoc_key = key;
            if (mrs_node_init(&node, &bus, &cfg, err, sizeof err) != 0) {
                fprintf(stderr, "secoc_check: %s\n", err);
                return 2;
            }
            puts("ok");
        } else if (strcmp(word, "plain") == 0) {
            cfg.secoc_key = NULL;
            if (mrs_node_init(&node, &bus, &cfg, err, sizeof err) != 0) {
                return 2;
            }
            puts("ok");
        } else if (strcmp(word, "rx") == 0 && sscanf(line, "%*s %159s %159s", a, b) == 2) {
            printf("%d\n", on_rx(a, b));
        } else if (strcmp(word, "stats") == 0) {
            printf("rx_rejected=%llu rx_auth_failed=%llu rx_unsynced=%llu\n",
                   (unsigned long long)node.stats.rx_rejected, (unsigned long long)node.stats.rx_auth_failed,
                   (unsigned long long)node.stats.rx_unsynced);
        } else if (strcmp(word, "ctl") == 0) {
            sent[0] = '\0';
            if (mrs_node_control(&node) != 0) {
                return 2;
            }
            puts(sent);
        } else if (strcmp(word, "cmd") == 0) {
            unsigned long long epoch;
            unsigned counter, alive, state, meas, i;
            double angle, phys[MRS_MAX_SIGNALS] = {0.0};
            uint8_t data[8];
            int len;
            if (sscanf(line, "%*s %llu %u %u %u %lf %u", &epoch, &counter, &alive, &state, &angle, &meas) != 6) {
                return 2;
            }
            node.signer.have_epoch = 1;
            node.signer.epoch = epoch;
            node.signer.counter = counter;
            node.cmd_alive = (uint8_t)((alive + 14u) % 15u); /* the counter before ALIVE */
            phys[MRS_SIG_CMD_STATE] = state;
            phys[MRS_SIG_CMD_ANGLE] = angle;
            phys[MRS_SIG_CMD_MEAS] = meas;
            len = mrs_node_build_frame(&node, MRS_MSG_CMD, phys, data);
            for (i = 0u; len > 0 && i < (unsigned)len; ++i) {
                printf("%02x", data[i]);
            }
            putchar('\n');
        } else {
            fprintf(stderr, "secoc_check: bad line: %s", line);
            return 2;
        }
        fflush(stdout);
    }
    mrs_node_free(&node);
    return 0;
}
