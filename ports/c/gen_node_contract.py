"""Writes mrs_contract.h/.c: the DBC as the C controller node (mrs_node.c) needs it, on top of
the cantools-generated codec.

    python ports/c/gen_node_contract.py DBC OUT_DIR

For every message: its frame ID, length, cycle time, ``MRS_ControlLoop`` flag, E2E data ID and
CRC byte, each signal's DBC range, and three functions that go through the generated codec
(``mrsteer_<msg>_unpack/_pack`` and the per-signal ``_decode``): unpack to physical values in
DBC signal order, the range check of every signal (as ``mrsteer_dbc.Contract.decode``), and
pack from physical values.  Packing rounds to the nearest raw value, ties to even, as the
Python cantools encoder does (``round((value - offset) / scale)``); the generated ``_encode``
functions truncate instead, which would make a C frame differ from the Python one by a bit.  A
signal with the DBC attribute ``MRS_RoundTowardZero`` packs as ``mrsteer_dbc.contract.toward_zero_raw``
does: the nearest raw value, one step back toward zero where that one decodes beyond the value.
For the SecOC messages the indices of the freshness and MAC fields and the AND mask that clears
the CRC byte and the MAC bits (``mrsteer_dbc.secoc.AuthFields``).  The names the code means
(messages, signals, ``CtrlStatus_Cause`` and ``CtrlStatus_Plausibility`` bits, ``MeasCounter``'s NONE) come from
``mrsteer_dbc.names``.  A signal with an ``SNA`` raw value (the DBC's value table) unpacks to NaN
at it, which the range check lets through for that signal only, and packs NaN as it.  Nothing here writes a bit position by hand: cantools owns the layouts.
"""

from __future__ import annotations

import sys
from pathlib import Path

import cantools
from cantools.database.can.c_source import camel_to_snake_case

from mrsteer_dbc import names
from mrsteer_dbc.contract import Contract, rounds_toward_zero, sna_raw

DB = "mrsteer"
MESSAGES = {  # names.py constant -> message
    "MSG_STEER": names.MSG_STEER, "MSG_YAW": names.MSG_YAW, "MSG_SPEED": names.MSG_SPEED,
    "MSG_REDUNDANT": names.MSG_REDUNDANT, "MSG_CMD": names.MSG_CMD, "MSG_STATUS": names.MSG_STATUS, "MSG_SYNC": names.MSG_SYNC,
}


def _c(x: float) -> str:
    return repr(float(x))


def _sig_consts() -> list[tuple[str, str, str]]:
    """(C macro, message, signal) for every ``SIG_*`` constant of names.py of the node's messages."""
    out = []
    for const, value in vars(names).items():
        if const.startswith("SIG_") and isinstance(value, str):
            msg = next((m for m in MESSAGES.values() if value.startswith(m.removeprefix("MRS_") + "_")), None)
            if msg is not None:  # the bench's signals are not the controller's
                out.append((f"MRS_{const}", msg, value))
    return out


def _mask(contract: Contract, msg) -> list[int]:
    """The AuthFields zero mask: every bit but the CRC byte's and the MAC's."""
    e2e = contract.e2e(msg.name)
    mask = [0xFF] * msg.length
    if e2e is not None:
        mask[e2e.crc_byte] = 0
    stem = msg.name.removeprefix("MRS_")
    mac = next((s for s in msg.signals if s.name == f"{stem}_MAC"), None)
    if mac is not None:
        for bit in range(mac.start, mac.start + mac.length):
            mask[bit // 8] &= ~(1 << (bit % 8)) & 0xFF
    return mask


def _functions(msg) -> str:
    m = f"{DB}_{camel_to_snake_case(msg.name)}"
    lo = [_c(s.minimum) for s in msg.signals]
    hi = [_c(s.maximum) for s in msg.signals]
    sna = [sna_raw(s) for s in msg.signals]
    unpack = []
    pack = []
    for i, s in enumerate(msg.signals):
        field = camel_to_snake_case(s.name)
        decode = f"{m}_{field}_decode(msg.{field})"
        unpack.append(f"    phys[{i}] = {decode};" if sna[i] is None else
                      f"    phys[{i}] = (msg.{field} == {sna[i]}) ? (double)NAN : {decode};")
        scale, offset = float(s.scale), float(s.offset)
        expr = f"phys[{i}]" if (scale, offset) == (1.0, 0.0) else f"(phys[{i}] - {_c(offset)}) / {_c(scale)}"
        cast = "int64_t" if s.is_signed else "uint64_t"
        raw = f"({cast})nearbyint({expr})"
        if rounds_toward_zero(s):  # contract.toward_zero_raw, statement for statement
            if sna[i] is not None:
                raise SystemExit(f"{s.name}: MRS_RoundTowardZero and an SNA value are not generated together")
            pack.append(f"    {{\n        double r = nearbyint({expr});\n"
                        f"        const double d = r * {_c(scale)} + {_c(offset)};\n"
                        f"        if (phys[{i}] > 0.0 && d > phys[{i}]) {{\n            r -= 1.0;\n"
                        f"        }} else if (phys[{i}] < 0.0 && d < phys[{i}]) {{\n            r += 1.0;\n        }}\n"
                        f"        msg.{field} = ({cast})r;\n    }}")
            continue
        pack.append(f"    msg.{field} = {raw};" if sna[i] is None else
                    f"    msg.{field} = (phys[{i}] != phys[{i}]) ? {sna[i]} : {raw};")
    unpack = "\n".join(unpack)
    sn = camel_to_snake_case(msg.name)
    return f"""
static const double {sn}_min[{len(lo)}] = {{{", ".join(lo)}}};
static const double {sn}_max[{len(hi)}] = {{{", ".join(hi)}}};
static const uint8_t {sn}_sna[{len(lo)}] = {{{", ".join("0u" if x is None else "1u" for x in sna)}}};

static int {sn}_unpack(double *phys, const uint8_t *data, size_t len)
{{
    struct {m}_t msg;
    if ({m}_unpack(&msg, data, len) != 0) {{
        return -1;
    }}
{unpack}
    return 0;
}}

static int {sn}_pack(uint8_t *out, size_t size, const double *phys)
{{
    struct {m}_t msg;
    (void){m}_init(&msg);
{chr(10).join(pack)}
    return {m}_pack(out, &msg, size);
}}
"""


def _desc(contract: Contract, msg) -> str:
    sn = camel_to_snake_case(msg.name)
    e2e = contract.e2e(msg.name)
    stem = msg.name.removeprefix("MRS_")
    idx = {s.name: i for i, s in enumerate(msg.signals)}

    def at(suffix: str) -> int:
        return idx.get(f"{stem}_{suffix}", -1)

    def bits(suffix: str) -> int:
        s = next((s for s in msg.signals if s.name == f"{stem}_{suffix}"), None)
        return s.length if s is not None else 0

    cycle = msg.cycle_time / 1000.0 if msg.cycle_time else 0.0
    mask = ", ".join(f"0x{b:02X}u" for b in _mask(contract, msg) + [0] * (8 - msg.length))
    return (f"    {{\"{msg.name}\", 0x{msg.frame_id:X}u, {msg.length}u, {len(msg.signals)}u, "
            f"{1 if e2e else 0}u, {e2e.data_id if e2e else 0}u, {e2e.crc_byte if e2e else 0}u, "
            f"{at('Counter')}, {_c(cycle)}, {1 if contract.is_control_loop(msg.name) else 0}u,\n"
            f"     {at('FvEpoch')}, {at('FvCounter')}, {bits('FvCounter')}u, {at('MAC')}, {bits('MAC')}u, {at('Epoch')},\n"
            f"     {{{mask}}},\n"
            f"     {sn}_min, {sn}_max, {sn}_sna, {sn}_unpack, {sn}_pack}}")


def header(contract: Contract) -> str:
    db = contract.db
    order = list(MESSAGES.values())
    msg_macros = "\n".join(f"#define MRS_{k} {order.index(v)}" for k, v in MESSAGES.items())
    sig_macros = []
    for macro, msg, sig in _sig_consts():
        i = [s.name for s in db.get_message_by_name(msg).signals].index(sig)
        sig_macros.append(f"#define {macro} {i} /* {sig} */")
    causes = "\n".join(f"#define MRS_{k} 0x{v:02X}u" for k, v in vars(names).items() if k.startswith("CAUSE_"))
    # Spelled as mrs_monitor.h spells them: a differing value is a macro redefinition, which
    # -Werror turns into a build error wherever both headers are included.
    plaus = "\n".join(f"#define MRS_{k} 0x{v:02X}u" for k, v in vars(names).items() if k.startswith("PLAUS_"))
    return f"""/* Generated by ports/c/gen_node_contract.py from {contract.path.name} and mrsteer_dbc.names: do not edit. */
#ifndef MRS_CONTRACT_H
#define MRS_CONTRACT_H

#include <stddef.h>
#include <stdint.h>

#define MRS_N_MESSAGES {len(order)}
#define MRS_MAX_SIGNALS {max(len(db.get_message_by_name(m).signals) for m in order)}

/* Messages (index into mrs_messages), as mrsteer_dbc.names names them. */
{msg_macros}

/* Signals: index into the physical-value array of their message. */
{chr(10).join(sig_macros)}

/* CtrlStatus_Cause bits and AuxSteerCmd_MeasCounter's NONE. */
{causes}
#define MRS_MEAS_NONE {names.MEAS_NONE}u

/* CtrlStatus_Plausibility bits. */
{plaus}

typedef struct {{
    const char *name;
    uint32_t frame_id;
    uint8_t length, n_signals;
    uint8_t e2e;
    uint16_t data_id;
    uint8_t crc_byte;
    int counter; /* index of the *_Counter signal, -1 without E2E */
    double cycle_s; /* GenMsgCycleTime in s, 0 if none */
    uint8_t control_loop; /* MRS_ControlLoop = 1: sent every control period */
    int fv_epoch, fv_counter; /* SecOC signal indices, -1 if absent */
    uint8_t fv_counter_bits;
    int mac;
    uint8_t mac_bits;
    int epoch; /* MRS_SecOCSync's *_Epoch signal index, -1 elsewhere */
    uint8_t zero_mask[8]; /* AND mask clearing the CRC byte and the MAC bits */
    const double *min, *max; /* every signal's DBC range, in signal order */
    const uint8_t *sna; /* 1: the signal has an SNA raw value, unpacked as NaN */
    /* Through the generated codec: physical values in signal order. */
    int (*unpack)(double *phys, const uint8_t *data, size_t len);
    int (*pack)(uint8_t *out, size_t size, const double *phys); /* bytes written, or < 0 */
}} mrs_msg_t;

extern const mrs_msg_t mrs_messages[MRS_N_MESSAGES];

/* Every signal within its DBC [min, max] and finite, or NaN where it has an SNA value
 * (mrsteer_dbc.Contract.decode). */
int mrs_in_range(const mrs_msg_t *m, const double *phys);

#endif
"""


def source(contract: Contract) -> str:
    msgs = [contract.db.get_message_by_name(m) for m in MESSAGES.values()]
    funcs = "".join(_functions(m) for m in msgs)
    descs = ",\n".join(_desc(contract, m) for m in msgs)
    return f"""/* Generated by ports/c/gen_node_contract.py from {contract.path.name}: do not edit. */
#include <math.h>

#include "{DB}.h"
#include "mrs_contract.h"
{funcs}
const mrs_msg_t mrs_messages[MRS_N_MESSAGES] = {{
{descs}
}};

int mrs_in_range(const mrs_msg_t *m, const double *phys)
{{
    unsigned i;
    for (i = 0u; i < m->n_signals; ++i) {{
        /* Written so that a NaN fails, unless it is the signal's SNA. */
        if (!(phys[i] >= m->min[i] && phys[i] <= m->max[i]) && !(m->sna[i] != 0u && isnan(phys[i]))) {{
            return 0;
        }}
    }}
    return 1;
}}
"""


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: gen_node_contract.py DBC OUT_DIR")
    c = Contract(sys.argv[1])
    out = Path(sys.argv[2])
    out.mkdir(parents=True, exist_ok=True)
    (out / "mrs_contract.h").write_text(header(c))
    (out / "mrs_contract.c").write_text(source(c))
