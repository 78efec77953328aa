"""The frame path of a node: ``RxLink`` decides whether a received frame is trusted, ``TxLink``
builds the frames a node sends.  Both nodes (the controller and the plant) use these and nothing
else to touch a payload.

**Receive** (``RxLink.accept``), the one place the checks are ordered:

1. not one of this link's messages (other ID, extended ID, error or remote frame): ignored;
2. length, 3. E2E CRC (and a counter value of 15, which profile 1 never sends), 4. every
   signal's DBC range: ``Contract.decode``, one cantools decode;
5. the SecOC MAC and freshness, when the message has a verifier;
6. the alive-counter sequence (``E2EReceiver``), last: the MAC is checked before the counter,
   so a forged frame cannot advance the sequence, and a frame that fails an earlier check
   never reaches the verifier's freshness state.

The first check that fails names the ``Rejected`` reason, which carries the ``CtrlStatus_Cause``
bit the controller reports for it (length, CRC, counter: E2E; range: RANGE; MAC: AUTH).

**Send** (``TxLink.frame``): the alive counter of each E2E message, then, for a message the
signer signs, the SecOC fields and the MAC, the E2E CRC last; encoded once.
"""

from __future__ import annotations

import enum
from typing import Iterable, Mapping

import can

from mrsteer_dbc.contract import Contract, Decoded
from mrsteer_dbc.e2e import AliveCounter, E2EReceiver, E2EStatus
from mrsteer_dbc.names import CAUSE_AUTH, CAUSE_E2E, CAUSE_RANGE
from mrsteer_dbc.secoc.frames import FrameSigner, FrameVerifier


class Rejected(enum.Enum):
    """Why ``RxLink.accept`` refused a frame, with the ``CtrlStatus_Cause`` bit it stands for
    (0 for a frame that was not this link's to judge)."""

    IGNORED = ("ignored", 0)
    LENGTH = ("length", CAUSE_E2E)
    CRC = ("crc", CAUSE_E2E)
    COUNTER_VALUE = ("counter value", CAUSE_E2E)  # 15: never sent by profile 1
    RANGE = ("range", CAUSE_RANGE)
    MAC = ("mac", CAUSE_AUTH)  # SecOC: forged, replayed or stale
    REPEATED = ("repeated", CAUSE_E2E)  # the same alive counter again
    WRONG_SEQUENCE = ("wrong sequence", CAUSE_E2E)  # the alive counter jumped too far

    def __init__(self, label: str, cause: int) -> None:
        self.label = label
        self.cause = cause


_BY_STATUS = {E2EStatus.BAD_LENGTH: Rejected.LENGTH, E2EStatus.BAD_CRC: Rejected.CRC,
              E2EStatus.BAD_COUNTER: Rejected.COUNTER_VALUE, E2EStatus.OUT_OF_RANGE: Rejected.RANGE,
              E2EStatus.REPEATED: Rejected.REPEATED, E2EStatus.WRONG_SEQUENCE: Rejected.WRONG_SEQUENCE}


class RxLink:
    """The receive side of one node: the messages it takes, their counter-sequence state and
    their SecOC verifiers (``verifiers``: message name to verifier, for the messages that are
    authenticated)."""

    def __init__(self, contract: Contract, names: Iterable[str],
                 verifiers: Mapping[str, FrameVerifier] | None = None, max_delta: int = 3) -> None:
        self.contract = contract
        verifiers = verifiers or {}
        self.receivers: dict[str, E2EReceiver] = {}
        self._rx: dict[int, tuple[E2EReceiver | None, FrameVerifier | None]] = {}
        for name in names:
            receiver = E2EReceiver(max_delta) if contract.e2e(name) is not None else None
            if receiver is not None:
                self.receivers[name] = receiver
            self._rx[contract.frame_id(name)] = (receiver, verifiers.get(name))
        unknown = set(verifiers) - {contract.name_of(fid) for fid in self._rx}
        if unknown:
            raise ValueError(f"verifiers for messages this link does not receive: {', '.join(sorted(unknown))}")

    def filters(self) -> list[dict[str, int | bool]]:
        """python-can receive filters for exactly this link's frames."""
        return [{"can_id": fid, "can_mask": 0x7FF, "extended": False} for fid in self._rx]

    def accept(self, msg: can.Message) -> Decoded | Rejected:
        """The frame decoded, if every check passes (its ``status`` then says how the counter
        advanced: OK, OK_SOME_LOST or INITIAL), else the first check that failed."""
        # The receive filter is not enough on its own: SocketCAN queues frames of every ID
        # between opening the socket and installing the filter.
        if msg.is_extended_id or msg.is_error_frame or msg.is_remote_frame:
            return Rejected.IGNORED
        frame_id = msg.arbitration_id
        rx = self._rx.get(frame_id)
        if rx is None:
            return Rejected.IGNORED
        data = bytes(msg.data)
        decoded = self.contract.decode(frame_id, data)
        assert decoded is not None  # every link message is in the DBC
        if decoded.status is not E2EStatus.OK:
            return _BY_STATUS[decoded.status]
        receiver, verifier = rx
        # Authenticate before the counter check: a forged frame must not advance the sequence.
        if verifier is not None and not verifier.verify(frame_id, data, decoded.signals):
            return Rejected.MAC
        if receiver is not None:
            status = receiver.check(decoded.counter)  # type: ignore[arg-type]  # E2E: always a counter
            if not status.accepted:
                return _BY_STATUS[status]
            decoded.status = status
        return decoded


class TxLink:
    """The send side of one node: an alive counter per E2E message and, when keyed, the signer
    of the messages it authenticates.  ``strict=False`` sends values outside the DBC ranges as
    far as each signal's bits carry them (saturated there: a sensor pegged past its range; the
    receiver range-checks)."""

    def __init__(self, contract: Contract, names: Iterable[str], signer: FrameSigner | None = None,
                 *, strict: bool = True) -> None:
        self.contract = contract
        self.signer = signer
        self.strict = strict
        self._ids = {name: contract.frame_id(name) for name in names}
        self._alive = {name: AliveCounter() for name in self._ids if contract.e2e(name) is not None}
        self._signed = frozenset(signer.fields) & set(self._ids) if signer is not None else frozenset()

    def counter(self, name: str) -> int:
        """The alive counter of the last ``name`` frame built."""
        return self._alive[name].value

    def payload(self, name: str, values: Mapping[str, float | str]) -> bytes:
        """The next ``name`` frame's payload: alive counter, SecOC fields and MAC when signed,
        E2E CRC."""
        alive = self._alive.get(name)
        counter = alive.next() if alive is not None else None
        if name in self._signed:
            assert self.signer is not None and counter is not None
            return self.signer.encode(name, values, counter, strict=self.strict)
        return self.contract.encode(name, values, counter, strict=self.strict)

    def frame(self, name: str, values: Mapping[str, float | str]) -> can.Message:
        """The next ``name`` frame, ready to send."""
        return can.Message(arbitration_id=self._ids[name], data=self.payload(name, values), is_extended_id=False)
