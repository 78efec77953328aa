"""The bus contract: ``mrsteer.dbc`` and what a frame means and whether to trust it
(installed as ``mrsteer_dbc``).  No clocks, no processes: the lowest layer, imported by all.

* ``names``: the message and signal names the code uses, the ``CtrlStatus_Cause`` bits.
* ``contract``: the DBC loaded with cantools; encode and decode with E2E and range checks.
* ``e2e``: the profile-1-style CRC, alive counter and receiver state.
* ``secoc``: optional SecOC-style authentication (AES-CMAC, freshness) of commands and sensors.
* ``link``: a node's frame path: ``RxLink`` (the one order of the receive checks, and the cause
  of a rejection) and ``TxLink`` (alive counter, signing, CRC last).
* ``busload``: worst-case bus load of the contract at a control rate.
* ``mrsteer.dbc``: the contract itself, the only place a frame layout is defined.

This package's namespace re-exports the names most code needs.
"""

from mrsteer_dbc.contract import DBC_PATH, Contract, ContractError, Decoded, load
from mrsteer_dbc.e2e import COUNTER_MODULO, AliveCounter, E2EConfig, E2EReceiver, E2EStatus, crc8_sae_j1850

__all__ = ["DBC_PATH", "COUNTER_MODULO", "AliveCounter", "Contract", "ContractError", "Decoded", "E2EConfig",
           "E2EReceiver", "E2EStatus", "crc8_sae_j1850", "load"]
