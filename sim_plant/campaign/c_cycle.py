"""The C port's control cycle for a batch of rows (``ports/c/mrs_cycle_batch.h``), loaded with
cffi: the batch engine steps its controllers, and the actuators' own authority limiters, through
it, so that campaigns run the code an ECU runs.

The extension ``sim_plant.campaign._c_cycle`` is compiled when the project is installed
(``ports/c/cffi_cycle.py``, ``setup.py``).  Without it (no C compiler then) ``require`` raises
``NotBuilt`` with one line saying so.

The law's calibration reaches C as the C node gets it: written as a calibration file
(``firmware_py.calibration_file``) and read by ``mrs_config_load``; the monitor's and the
limiter's configurations are the C defaults at the step (and the limiter's magnitude), as the
node's.  Inputs and outputs are numpy arrays allocated once per batch; cffi passes their buffers.
"""

from __future__ import annotations

import hashlib
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from firmware_py import calibration_file
from firmware_py import model_regulator as mr

_WHY = ""  # why the extension cannot be imported
try:
    from sim_plant.campaign._c_cycle import ffi, lib
except ImportError as exc:  # (not built: no C compiler when the project was installed)
    ffi = lib = None
    _WHY = str(exc)


class NotBuilt(ImportError):
    """The C cycle's extension is not there."""


#: The port's sources, where this is a checkout (an editable install); None elsewhere.
PORT = Path(__file__).resolve().parents[2] / "ports" / "c"


def built_from_the_port() -> bool:
    """The extension was compiled from the port's sources as they are now (True where there is
    no checkout to compare with): ``ports/c/cffi_cycle.py`` stores their digest in it."""
    files = ffi.string(lib.mrs_c_cycle_files()).decode().split(",")
    if not all((PORT / name).is_file() for name in files):
        return True
    h = hashlib.sha256()
    for name in files:
        h.update(name.encode() + b"\0" + (PORT / name).read_bytes() + b"\0")
    return h.hexdigest() == ffi.string(lib.mrs_c_cycle_digest()).decode()


def require() -> None:
    """Raise ``NotBuilt`` (one line) where the extension cannot be imported, or was built from
    other sources than the checkout's ``ports/c`` now has."""
    if lib is None:
        raise NotBuilt("the C control cycle (sim_plant/campaign/_c_cycle, built from ports/c by `pip install -e .`) "
                       f"cannot be imported ({_WHY}): install the project again where a C compiler (gcc) is found")
    if not built_from_the_port():
        raise NotBuilt("the C control cycle (sim_plant/campaign/_c_cycle) was built from other sources than ports/c "
                       "has now: build it again with `pip install -e .` (make venv does)")


#: The per-period inputs, in the order of ``mrs_cycle_batch_inputs_t``'s double arrays.
INPUTS = ("delta_driver", "yaw_rate", "speed", "lat_accel", "delta_driver_redundant", "yaw_rate_redundant",
          "speed_redundant", "monitor_driver")
#: The per-period outputs, ``mrs_cycle_batch_outputs_t``'s arrays: their C and numpy types.
OUTPUTS = {"command": ("double *", np.float64), "plausibility": ("uint8_t *", np.uint8),
           "reported": ("uint8_t *", np.uint8), "status": ("uint8_t *", np.uint8),
           "monitor_flags": ("uint16_t *", np.uint16), "authority_flags": ("uint8_t *", np.uint8)}


def _ptr(ctype: str, a: np.ndarray) -> Any:
    """A C pointer of ``ctype`` to ``a``'s buffer (``a`` outlives its use: the caller keeps it)."""
    return ffi.cast(ctype, ffi.from_buffer(a))


def law_config(config: mr.ControllerConfig) -> Any:
    """``config`` as the C law's ``mrs_config_t``, through a calibration file (the C node's one mapping)."""
    require()
    g = ffi.new("mrs_config_t *")
    err = ffi.new("char[]", 256)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "campaign.cfg"
        path.write_text(calibration_file.dumps(config))
        if lib.mrs_config_load(str(path).encode(), g, err, 256) != 0:
            raise ValueError(f"the C port cannot read the calibration: {ffi.string(err).decode()}")
    return g


def _authority_config(ts: float, u_max: float) -> Any:
    """The C limiter's defaults at ``ts`` with the magnitude ``u_max`` (as the C node's)."""
    cfg = ffi.new("mrs_authority_config_t *")
    lib.mrs_authority_default_config(cfg)
    cfg.ts, cfg.u_max = ts, u_max
    return cfg


class CycleBatch:
    """n controllers of one calibration, each the C cycle (``mrs_cycle_step``): the law
    ``config``, the monitor's defaults at ``config.ts``, the limiter's at its magnitude
    ``u_max``.  ``step`` runs one period of every row; its outputs are this object's arrays
    (``OUTPUTS``), overwritten by the next period."""

    def __init__(self, config: mr.ControllerConfig, u_max: float, n: int) -> None:
        require()
        self.n = n
        self.coeffs = ffi.new("mrs_cycle_coeffs_t *")
        monitor = ffi.new("mrs_monitor_config_t *")
        lib.mrs_monitor_default_config(monitor)
        monitor.ts = config.ts
        rc = lib.mrs_cycle_configure(law_config(config), monitor, _authority_config(config.ts, u_max), self.coeffs)
        if rc != 0:
            raise ValueError(f"the C cycle refuses the calibration (mrs_cycle_configure: {rc})")
        self.states = ffi.new("mrs_cycle_state_t[]", n)
        lib.mrs_cycle_batch_reset(n, self.states)
        self.inputs = np.full((len(INPUTS), n), np.nan)
        self.monitor_steps = np.ones(n, dtype=np.int32)  # one yaw-rate sample every period
        self.starting = np.zeros(n, dtype=np.uint8)
        self._in = ffi.new("mrs_cycle_batch_inputs_t *")
        for name, row in zip(INPUTS, self.inputs):
            setattr(self._in, name, _ptr("double *", row))
        self._in.monitor_steps = _ptr("int32_t *", self.monitor_steps)
        self._in.starting = _ptr("uint8_t *", self.starting)
        self.out = {name: np.zeros(n, dtype=dtype) for name, (_, dtype) in OUTPUTS.items()}
        self._out = ffi.new("mrs_cycle_batch_outputs_t *")
        for name, (ctype, _) in OUTPUTS.items():
            setattr(self._out, name, _ptr(ctype, self.out[name]))

    def step(self, delta_driver: np.ndarray, delta_driver_redundant: np.ndarray, yaw_rate: np.ndarray,
             lat_accel: np.ndarray, speed: np.ndarray, yaw_rate_redundant: np.ndarray,
             speed_redundant: np.ndarray) -> np.ndarray:
        """One period of every row on its samples (the monitor's first step on ``delta_driver``
        too): the limited commands (``out["command"]``)."""
        x = self.inputs
        x[0], x[1], x[2], x[3] = delta_driver, yaw_rate, speed, lat_accel
        x[4], x[5], x[6], x[7] = delta_driver_redundant, yaw_rate_redundant, speed_redundant, delta_driver
        lib.mrs_cycle_batch(self.n, self.coeffs, self.states, self._in, self._out)
        return self.out["command"]


class AuthorityBatch:
    """n authority limiters without cut or fade (an actuator's own, on its last status frame's
    bits): ``mrs_authority_step`` per row, the defaults at ``ts`` and ``u_max``."""

    def __init__(self, ts: float, u_max: float, n: int) -> None:
        require()
        self.n = n
        self.coeffs = ffi.new("mrs_authority_coeffs_t *")
        if lib.mrs_authority_configure(_authority_config(ts, u_max), self.coeffs) != 0:
            raise ValueError(f"the C limiter refuses ts {ts:g} s, u_max {u_max:g} rad")
        self.states = ffi.new("mrs_authority_state_t[]", n)
        lib.mrs_authority_batch_reset(n, self.states)
        self.request, self.bits, self.u = np.zeros(n), np.zeros(n, dtype=np.uint8), np.zeros(n)
        self._request, self._bits, self._u = (_ptr("double *", self.request), _ptr("uint8_t *", self.bits),
                                              _ptr("double *", self.u))

    def step(self, u_request: np.ndarray, plaus_bits: np.ndarray) -> np.ndarray:
        """The commands allowed this period (this object's array, overwritten by the next)."""
        self.request[:] = u_request
        self.bits[:] = plaus_bits
        lib.mrs_authority_batch(self.n, self.coeffs, self.states, self._request, self._bits, self._u)
        return self.u
