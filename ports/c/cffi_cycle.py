"""The C control cycle as a Python extension (cffi, API mode): ``sim_plant.campaign._c_cycle``,
compiled when the project is installed (``setup.py``'s ``cffi_modules``; ``pip install -e .``).

What it compiles is the port itself (``mrs_controller.c``, ``mrs_monitor.c``, ``mrs_cycle.c``,
``mrs_config.c`` and the batch loop ``mrs_cycle_batch.c``) in float64 with the flags the port's
Makefile uses for its bit-for-bit checks (``-std=c99 -O2 -ffp-contract=off``: no fused
multiply-add, so every operation rounds as Python's).  The declarations below are the part of
the headers Python calls; ``...`` leaves a struct's layout to the compiler.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

from cffi import FFI

HERE = Path(__file__).resolve().parent
SOURCES = ("mrs_controller.c", "mrs_monitor.c", "mrs_cycle.c", "mrs_config.c", "mrs_cycle_batch.c")
HEADERS = ("mrs_controller.h", "mrs_monitor.h", "mrs_cycle.h", "mrs_config.h", "mrs_cycle_batch.h",
           "mrs_defaults.h")
MODULE = "sim_plant.campaign._c_cycle"


def digest(files: tuple[str, ...], where: Path) -> str:
    """SHA-256 over ``files`` of ``where`` in their order: the module carries its sources' digest,
    so that ``sim_plant.campaign.c_cycle`` finds a build older than ``ports/c``."""
    h = hashlib.sha256()
    for name in files:
        h.update(name.encode() + b"\0" + (where / name).read_bytes() + b"\0")
    return h.hexdigest()

CDEF = """
typedef struct { double ts; double aux_limit; ...; } mrs_config_t;
typedef struct { double ts; ...; } mrs_monitor_config_t;
typedef struct { double ts; double u_max; ...; } mrs_authority_config_t;
typedef struct { ...; } mrs_authority_coeffs_t;
typedef struct { ...; } mrs_authority_state_t;
typedef struct { ...; } mrs_cycle_coeffs_t;
typedef struct { ...; } mrs_cycle_state_t;

typedef struct {
    const double *delta_driver;
    const double *yaw_rate;
    const double *speed;
    const double *lat_accel;
    const double *delta_driver_redundant;
    const double *yaw_rate_redundant;
    const double *speed_redundant;
    const double *monitor_driver;
    const int32_t *monitor_steps;
    const uint8_t *starting;
} mrs_cycle_batch_inputs_t;

typedef struct {
    double *command;
    uint8_t *plausibility;
    uint8_t *reported;
    uint8_t *status;
    uint16_t *monitor_flags;
    uint8_t *authority_flags;
} mrs_cycle_batch_outputs_t;

int mrs_config_load(const char *path, mrs_config_t *g, char *err, size_t err_len);
void mrs_monitor_default_config(mrs_monitor_config_t *cfg);
void mrs_authority_default_config(mrs_authority_config_t *cfg);
int mrs_authority_configure(const mrs_authority_config_t *cfg, mrs_authority_coeffs_t *c);
int mrs_cycle_configure(const mrs_config_t *law, const mrs_monitor_config_t *monitor,
                        const mrs_authority_config_t *authority, mrs_cycle_coeffs_t *c);
void mrs_cycle_batch_reset(int32_t n, mrs_cycle_state_t *states);
void mrs_cycle_batch(int32_t n, const mrs_cycle_coeffs_t *c, mrs_cycle_state_t *states,
                     const mrs_cycle_batch_inputs_t *in, const mrs_cycle_batch_outputs_t *out);
void mrs_authority_batch_reset(int32_t n, mrs_authority_state_t *states);
void mrs_authority_batch(int32_t n, const mrs_authority_coeffs_t *c, mrs_authority_state_t *states,
                         const double *u_request, const uint8_t *plaus_bits, double *u);
const char *mrs_c_cycle_files(void);
const char *mrs_c_cycle_digest(void);
"""

ffibuilder = FFI()
ffibuilder.cdef(CDEF)
ffibuilder.set_source(
    MODULE,
    '#include "mrs_config.h"\n#include "mrs_cycle_batch.h"\n'
    f'static const char *mrs_c_cycle_files(void) {{ return "{",".join(SOURCES + HEADERS)}"; }}\n'
    f'static const char *mrs_c_cycle_digest(void) {{ return "{digest(SOURCES + HEADERS, HERE)}"; }}\n',
    # (setuptools takes paths relative to setup.py's directory, where it runs)
    sources=[os.path.relpath(HERE / name) for name in SOURCES],
    include_dirs=[os.path.relpath(HERE)],
    extra_compile_args=["-std=c99", "-O2", "-ffp-contract=off"],
    libraries=["m"],
    # without a C compiler the install goes on without the module (a warning); the campaign
    # command then says in one line that it is missing (sim_plant.campaign.c_cycle.require)
    optional=True,
)

if __name__ == "__main__":
    ffibuilder.compile(verbose=True)
