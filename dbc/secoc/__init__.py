"""Optional authentication in the style of AUTOSAR SecOC of ``MRS_AuxSteerCmd`` (``command``)
and of the sensor frames (``sensors``), with the actuator as the freshness master that issues
epochs in ``MRS_SecOCSync``.

* ``keys``: the shared 128-bit key (file or ``$MRSTEER_SECOC_KEY``) and ``SecOCError``.
* ``cmac``: truncated AES-CMAC, the 64-bit freshness value, the frame MAC.
* ``frames``: an authenticated message's fields, the one signing path (FV fields, MAC, E2E CRC
  last), and the signer and verifier shapes ``mrsteer_dbc.link`` uses.
* ``command``: ``CommandSigner`` (controller) and ``CommandVerifier`` (actuator, epochs).
* ``sensors``: ``SensorSigner`` (vehicle) and ``SensorVerifier`` (controller).

The receiver checks E2E length, CRC and range, then the MAC, and only then the alive-counter
sequence, so a forged frame cannot advance the sequence (``mrsteer_dbc.link.RxLink``).
This namespace only re-exports.
"""

from mrsteer_dbc.secoc.cmac import COUNTER_BITS, TruncatedCmac, epoch_named, frame_mac, freshness
from mrsteer_dbc.secoc.command import (COMMAND, EPOCH_ORIGIN_S, SYNC, CommandSigner, CommandVerifier, Layout,
                                       VerifyStats)
from mrsteer_dbc.secoc.frames import AuthFields, FrameSigner, FrameVerifier, sign_frame
from mrsteer_dbc.secoc.keys import KEY_BYTES, KEY_ENV, SecOCError, load_key
from mrsteer_dbc.secoc.sensors import (SENSOR_FV_LOW_BITS, SENSOR_MAX_ADVANCE, SENSORS, SensorFields, SensorSigner,
                                       SensorVerifier, counter_advance)

__all__ = ["COMMAND", "COUNTER_BITS", "EPOCH_ORIGIN_S", "KEY_BYTES", "KEY_ENV", "SENSORS", "SENSOR_FV_LOW_BITS",
           "SENSOR_MAX_ADVANCE", "SYNC", "AuthFields", "CommandSigner", "CommandVerifier", "FrameSigner",
           "FrameVerifier", "Layout", "SecOCError", "SensorFields", "SensorSigner", "SensorVerifier",
           "TruncatedCmac", "VerifyStats", "counter_advance", "epoch_named", "frame_mac", "freshness", "load_key",
           "sign_frame"]
