"""The fallback bus's wire format, shared by its client (``fallback_bus``) and its broker
(``fallback_broker``): where a channel's socket lives and how a frame is packed into one
``SOCK_SEQPACKET`` packet (docs/can-runtime.md describes it for clients in other languages)."""

from __future__ import annotations

import os
import struct
from pathlib import Path

from can import CanInitializationError, Message

DEFAULT_CHANNEL = "mrsteer0"
INTERFACE_NAME = "mrsteer"
FRAME = struct.Struct("<cBdIBB")  # type b"F", flags, timestamp, arbitration id, dlc, data length
STAMP = struct.Struct("<d")  # the timestamp field of FRAME, at offset 2
FILTER = struct.Struct("<IIb")  # can_id, can_mask, extended (-1: either)
OPTIONS = struct.Struct("<cB")  # type b"O", receive_own
MAX_PACKET = FRAME.size + 64

F_EXTENDED, F_REMOTE, F_ERROR, F_FD, F_BRS, F_ESI, F_OWN = 1, 2, 4, 8, 16, 32, 64


def socket_dir() -> Path:
    return Path(os.environ.get("MRSTEER_BUS_DIR") or f"/tmp/mrsteer-bus-{os.getuid()}")


def socket_path(channel: str) -> Path:
    if not channel or "/" in channel or channel.startswith("."):
        raise ValueError(f"invalid fallback-bus channel name {channel!r}")
    return socket_dir() / f"{channel}.sock"


def private_dir(path: Path) -> None:
    path.mkdir(mode=0o700, parents=True, exist_ok=True)
    st = path.stat()
    if st.st_uid != os.getuid() or st.st_mode & 0o077:
        raise CanInitializationError(f"{path} must be a directory owned by you with mode 0700")


def pack_frame(msg: Message, flags_extra: int = 0) -> bytes:
    flags = flags_extra
    if msg.is_extended_id:
        flags |= F_EXTENDED
    if msg.is_remote_frame:
        flags |= F_REMOTE
    if msg.is_error_frame:
        flags |= F_ERROR
    if msg.is_fd:
        flags |= F_FD
    if msg.bitrate_switch:
        flags |= F_BRS
    if msg.error_state_indicator:
        flags |= F_ESI
    data = bytes(msg.data or b"")
    return FRAME.pack(b"F", flags, msg.timestamp or 0.0, msg.arbitration_id, msg.dlc, len(data)) + data


def unpack_frame(packet: bytes, channel: str) -> Message:
    _, flags, stamp, arb, dlc, n = FRAME.unpack_from(packet)
    return Message(
        timestamp=stamp,
        arbitration_id=arb,
        is_extended_id=bool(flags & F_EXTENDED),
        is_remote_frame=bool(flags & F_REMOTE),
        is_error_frame=bool(flags & F_ERROR),
        is_fd=bool(flags & F_FD),
        bitrate_switch=bool(flags & F_BRS),
        error_state_indicator=bool(flags & F_ESI),
        dlc=dlc,
        data=packet[FRAME.size:FRAME.size + n],
        channel=channel,
        is_rx=not flags & F_OWN,
    )
