/* The C port's step(), plausibility monitor and authority limiter on the per-step inputs of a
 * log replay (mrsteer replay --impl c).
 *
 *   mrs_replay CONFIG.cfg [INPUTS]    (INPUTS: a file, or standard input when absent or "-")
 *
 * CONFIG is a calibration file (the key = value format of firmware_py/calibration_file.py,
 * read by mrs_config_load; its ts and aux_limit are the node's effective ones). Each input line
 * is one controller cycle,
 * "DELTA_DRIVER YAW_RATE SPEED [LAT_ACCEL DELTA_DRIVER_2 [STEPS [YAW_RATE_2 [SPEED_2 [DELTA_DRIVER_MONITOR
 *  [STARTING]]]]]]"
 * (rad, rad/s, m/s, m/s^2, rad; "nan" for an input the receive side found invalid; the redundant
 * pair absent counts as invalid; STEPS the monitor's steps in the cycle, 0 to MRS_REPLAY_MAX_STEPS:
 * node.py's monitor_steps, 0 when it holds its verdict; absent counts as 1; YAW_RATE_2 the yaw-rate
 * sensor's second element, absent or nan when there is none; SPEED_2 the second speed, likewise;
 * DELTA_DRIVER_MONITOR the driver's angle of the monitor's first step, the one that came with a new
 * redundant sample (node.py's monitor_driver_angle), absent: DELTA_DRIVER; STARTING 1 in a cycle of
 * the node's start state (node.py's _still_starting, its inputs not all received yet), absent: 0), as
 * sim_plant/harness/replay.py extracts them from the frames. Each cycle is mrs_cycle_step, as in
 * mrs_node_control: the monitor (STEPS times, the first with DELTA_DRIVER_MONITOR) on the inputs
 * and the previous line's command, u_req = mrs_step(..., its suspicion of the yaw rate), the
 * limiter on u_req; each output line is
 * "U STATE FAULT_FLAGS PLAUSIBILITY" (U to 17 significant digits; STATE is the reported one,
 * mrs_reported_state). The frame decoding, E2E, freshness, start state and cause bits stay on the
 * Python side: this driver isolates the law and its guards, so a mismatch it shows is the
 * port's, not the receive path's. Exit 2 on unreadable input.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "mrs_config.h"
#include "mrs_controller.h"
#include "mrs_cycle.h"
#include "mrs_monitor.h"

#define LINE_MAX_LEN 4096
#define MRS_REPLAY_MAX_STEPS 100 /* more than any input's timeout in cycles */

static int fail(const char *what, const char *arg)
{
    fprintf(stderr, "mrs_replay: %s: %s\n", what, arg);
    return 2;
}

int main(int argc, char **argv)
{
    mrs_config_t g;
    mrs_monitor_config_t mon_cfg;
    mrs_authority_config_t auth_cfg;
    mrs_cycle_coeffs_t c;
    mrs_cycle_state_t s; /* the command sent last and the monitor's bits are held in it */
    mrs_cycle_inputs_t ci;
    int rc;
    char err[256];
    char line[LINE_MAX_LEN];
    FILE *in = stdin;
    long n = 0;

    if (argc < 2 || argc > 3) {
        return fail("usage", "mrs_replay CONFIG.cfg [INPUTS]");
    }
    if (mrs_config_load(argv[1], &g, err, sizeof err) != 0) {
        return fail("cannot read", err);
    }
    mrs_monitor_default_config(&mon_cfg);
    mon_cfg.ts = (double)g.ts;
    mrs_authority_default_config(&auth_cfg);
    auth_cfg.ts = (double)g.ts;
    auth_cfg.u_max = (double)g.aux_limit;
    rc = mrs_cycle_configure(&g, &mon_cfg, &auth_cfg, &c);
    if (rc == MRS_CYCLE_BAD_LAW) {
        return fail("invalid calibration in", argv[1]);
    }
    if (rc != 0) {
        return fail("no plausibility monitor or authority limiter at the period of", argv[1]);
    }
    mrs_cycle_reset(&s);
    if (argc == 3 && strcmp(argv[2], "-") != 0) {
        in = fopen(argv[2], "r");
        if (in == NULL) {
            return fail("cannot read", argv[2]);
        }
    }
    while (fgets(line, sizeof line, in) != NULL) {
        double v[10] = {0.0, 0.0, 0.0, NAN, NAN, 1.0, NAN, NAN, NAN, 0.0};
        char *p = line, *end;
        int k;
        ++n;
        for (k = 0; k < 10; ++k) {
            const double x = strtod(p, &end);
            if (end == p) {
                if (k < 3) {
                    fprintf(stderr, "mrs_replay: line %ld: expected three or five to ten numbers\n", n);
                    return 2;
                }
                break;
            }
            v[k] = x;
            p = end;
        }
        if (k == 4 || !(v[5] >= 0.0 && v[5] <= (double)MRS_REPLAY_MAX_STEPS && v[5] == floor(v[5])) ||
            !(v[9] == 0.0 || v[9] == 1.0)) {
            fprintf(stderr,
                    "mrs_replay: line %ld: expected three or five to ten numbers (the sixth a count of steps, the tenth "
                    "0 or 1)\n", n);
            return 2;
        }
        if (strspn(p, " \t\r\n") != strlen(p)) {
            fprintf(stderr, "mrs_replay: line %ld: text after the numbers (at most ten)\n", n);
            return 2;
        }
        if (k < 9) {
            v[8] = v[0];
        }
        ci.delta_driver = v[0];
        ci.yaw_rate = v[1];
        ci.speed = v[2];
        ci.lat_accel = v[3];
        ci.delta_driver_redundant = v[4];
        ci.monitor_steps = (int32_t)v[5];
        ci.yaw_rate_redundant = v[6];
        ci.speed_redundant = v[7];
        ci.monitor_driver = v[8];
        ci.starting = v[9] != 0.0;
        (void)mrs_cycle_step(&c, &s, &ci);
        printf("%.17g %u %u %u\n", s.command, s.reported, (unsigned)s.law.fault_flags, (unsigned)s.plausibility);
    }
    if (in != stdin) {
        fclose(in);
    }
    return 0;
}
