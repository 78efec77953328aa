/*
 * The calibration file of the C port: the key = value lines of tests/vectors/<config>.cfg
 * (`mrsteer vectors` writes them from ControllerConfig), read into an mrs_config_t.
 * Shared by run_vectors (which also compares the "c.*" coefficient lines) and mrs_node
 * (--calibration FILE). '#' starts a comment line; blank lines are skipped.
 */
#ifndef MRS_CALIB_H
#define MRS_CALIB_H

#include <stddef.h>

#include "mrs_controller.h"

/* Called for each "c.<name> = value" line (the coefficients configure() gave); may be NULL. */
typedef void (*mrs_calib_coeff_fn)(void *ctx, const char *key, double value);

/* Reads path over the defaults (mrs_default_config). 0 on success; otherwise -1 with a one-line
 * reason in err (the file, the line number and what is wrong): an unreadable file, a line
 * without '=', an unknown key, a value that is not a number or q_form/method name. */
int mrs_calib_read(const char *path, mrs_config_t *cfg, mrs_calib_coeff_fn coeff, void *ctx, char *err,
                   size_t err_len);

#endif
