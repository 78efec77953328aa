/*
 * mrsteer calibration files: the `key = value` format of firmware_py/calibration_file.py
 * (the .cfg files in tests/vectors, `mrsteer controller --calibration FILE`). Tables are comma-separated;
 * `none` marks an unset constant gain; `#` comments and `c.` coefficient lines are skipped.
 * Not part of the controller proper: file I/O for the process and the test drivers.
 */
#ifndef MRS_CONFIG_H
#define MRS_CONFIG_H

#include <stddef.h>

#include "mrs_controller.h"

/* Fill *g from the file at path, starting from mrs_default_config(). Returns 0 on success;
 * otherwise -1 with a one-line reason (file, line, key) in err. The calibration is not
 * validated here: mrs_configure() does that. */
int mrs_config_load(const char *path, mrs_config_t *g, char *err, size_t err_len);

#endif
