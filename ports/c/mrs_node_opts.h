/* The command line of mrs_node (the flags of `mrsteer controller` that apply, plus
 * --calibration FILE): parsed and checked as firmware_py/controller/main.py checks them. */
#ifndef MRS_NODE_OPTS_H
#define MRS_NODE_OPTS_H

#include "mrs_node_core.h"

#define MRS_NODE_PROG "mrs_node"

typedef struct {
    int socketcan; /* else the fallback bus */
    const char *channel;
    double rate_hz;
    int sensors_trigger;
    int sync; /* clock trigger: phase lock */
    double sync_offset; /* s */
    double duration; /* s of wall time; 0: until a signal */
    double slow_motion; /* wall time per period over the period (a slow machine's bench); 1: real time */
    const char *stats_out;
    int rt_priority, cpu; /* cpu -1: not pinned */
    uint8_t key[MRS_SECOC_KEY_BYTES];
} mrs_node_opts_t;

/* -1 to run; otherwise the exit status (0 after --help; 2 after a usage error, said on stderr
 * in one line). cfg->secoc_key points into o->key when a key was given. */
int mrs_node_parse(int argc, char **argv, mrs_node_opts_t *o, mrs_node_config_t *cfg);

#endif
