/* The C port's step() on the per-step inputs of a log replay (mrsteer replay --impl c).
 *
 *   mrs_replay CONFIG.cfg [INPUTS]    (INPUTS: a file, or standard input when absent or "-")
 *
 * CONFIG is a calibration file (the key = value format of firmware_py/calibration_file.py,
 * read by mrs_config_load). Each input line is one controller
 * cycle, "DELTA_DRIVER YAW_RATE SPEED" (rad, rad/s, m/s; "nan" for an input the receive side
 * found invalid), as sim_plant/harness/replay.py extracts them from the frames; each output line
 * is "U STATUS FAULT_FLAGS" after mrs_step (U to 17 significant digits). The frame decoding,
 * E2E, freshness and cause bits stay on the Python side: this driver isolates the law, so a
 * mismatch it shows is the port's, not the receive path's. Exit 2 on unreadable input.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "mrs_config.h"
#include "mrs_controller.h"

#define LINE_MAX_LEN 4096

static int fail(const char *what, const char *arg)
{
    fprintf(stderr, "mrs_replay: %s: %s\n", what, arg);
    return 2;
}

int main(int argc, char **argv)
{
    mrs_config_t g;
    mrs_coeffs_t c;
    mrs_state_t s;
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
    if (mrs_configure(&g, &c) != 0) {
        return fail("invalid calibration in", argv[1]);
    }
    if (argc == 3 && strcmp(argv[2], "-") != 0) {
        in = fopen(argv[2], "r");
        if (in == NULL) {
            return fail("cannot read", argv[2]);
        }
    }
    mrs_init_state(&s);
    while (fgets(line, sizeof line, in) != NULL) {
        double v[3];
        char *p = line, *end;
        int k;
        mrs_real_t u;
        ++n;
        for (k = 0; k < 3; ++k) {
            v[k] = strtod(p, &end);
            if (end == p) {
                fprintf(stderr, "mrs_replay: line %ld: expected three numbers\n", n);
                return 2;
            }
            p = end;
        }
        u = mrs_step(&c, &s, (mrs_real_t)v[0], (mrs_real_t)v[1], (mrs_real_t)v[2]);
        printf("%.17g %u %u\n", (double)u, (unsigned)s.status, (unsigned)s.fault_flags);
    }
    if (in != stdin) {
        fclose(in);
    }
    return 0;
}
