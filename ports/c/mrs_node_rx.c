/*
 * The C node's receive chain, the one path every received frame takes (declared in
 * mrs_node_core.h): C99 port of mrsteer_dbc.link.RxLink.accept and
 * firmware_py.controller.node.ControllerNode.receive for every message the node takes, the three
 * sensor messages, MRS_RedundantSensors and, keyed, MRS_SecOCSync:
 *
 *   outside the receive filters (another ID, an extended ID): IGNORED and not counted, as a
 *   frame python-can's filters never deliver; a remote or error frame: IGNORED, counted;
 *   length (exactly the DBC's) -> E2E CRC -> the generated codec's unpack -> alive counter value
 *   15 -> every signal's DBC range -> SecOC MAC and freshness when keyed (mrs_secoc.c) ->
 *   alive-counter sequence (mrs_e2e_check_counter), last.
 *
 * The MAC is checked before the counter so that a forged frame cannot advance the sequence.
 * This file is what make fuzz fuzzes (fuzz_rx.c), make coverage measures and make misra checks
 * (docs/porting.md, "Rigor"); written as MISRA C:2012 asks, with no deviation of its own.
 */
#include "mrs_node_core.h"

#include "mrs_contract.h"

#define MRS_N_RX_IDS 5u /* the four inputs and MRS_SecOCSync */

/* The CtrlStatus_Cause bit a rejection stands for (mrsteer_dbc.link.Rejected's cause). */
static unsigned cause_of(mrs_rx_verdict_t v)
{
    unsigned cause;
    switch (v) {
    case MRS_RX_RANGE:
        cause = MRS_CAUSE_RANGE;
        break;
    case MRS_RX_MAC:
        cause = MRS_CAUSE_AUTH;
        break;
    default: /* length, CRC, counter value, repeated, wrong sequence (never accepted or ignored) */
        cause = MRS_CAUSE_E2E;
        break;
    }
    return cause;
}

size_t mrs_node_filter_ids(int keyed, uint32_t ids[8])
{
    static const int msgs[MRS_N_RX_IDS] = {MRS_MSG_STEER, MRS_MSG_YAW, MRS_MSG_SPEED, MRS_MSG_REDUNDANT, MRS_MSG_SYNC};
    size_t n = (size_t)MRS_N_RX_IDS;
    size_t i;
    if (keyed == 0) {
        n = (size_t)MRS_N_RX_IDS - (size_t)1u; /* no MRS_SecOCSync */
    }
    for (i = 0u; i < n; ++i) {
        ids[i] = mrs_messages[msgs[i]].frame_id;
    }
    return n;
}

/* The alive-counter sequence check, last (none without E2E: seq NULL). */
static mrs_rx_verdict_t sequence(mrs_e2e_receiver_t *seq, const mrs_msg_t *m, const double *phys)
{
    mrs_e2e_status_t st = MRS_E2E_OK;
    mrs_rx_verdict_t v = MRS_RX_ACCEPTED;
    if (seq != NULL) {
        st = mrs_e2e_check_counter(seq, (uint8_t)phys[m->counter]);
    }
    if (st == MRS_E2E_REPEATED) {
        v = MRS_RX_REPEATED;
    } else if (st == MRS_E2E_WRONG_SEQUENCE) {
        v = MRS_RX_WRONG_SEQUENCE;
    } else {
        v = MRS_RX_ACCEPTED;
    }
    return v;
}

/* SecOC: the sync's MAC and epoch, or a sensor frame's MAC and freshness; nonzero if authentic. */
static int authentic(mrs_node_t *n, int msg, const mrs_frame_t *f, const double *phys)
{
    int ok;
    if (msg == MRS_MSG_SYNC) {
        ok = mrs_signer_accept_sync(&n->signer, n->cmac, &mrs_messages[msg], phys);
    } else {
        ok = mrs_sensor_verify(&n->verifier, n->cmac, msg, f->data, phys);
    }
    return ok;
}

/* The checks on the decoded frame: counter value, range, MAC (keyed), counter sequence (seq:
 * NULL for a message without E2E). The MAC is checked before the counter: a forged frame must
 * not advance the sequence. */
static mrs_rx_verdict_t check_decoded(mrs_node_t *n, int msg, mrs_e2e_receiver_t *seq, const mrs_frame_t *f,
                                      const double *phys)
{
    const mrs_msg_t *m = &mrs_messages[msg];
    mrs_rx_verdict_t v = MRS_RX_ACCEPTED;
    if ((m->e2e != 0u) && (phys[m->counter] >= (double)MRS_E2E_COUNTER_MODULO)) {
        v = MRS_RX_COUNTER_VALUE;
    } else if (mrs_in_range(m, phys) == 0) {
        v = MRS_RX_RANGE;
    } else if (n->keyed == 0) {
        v = sequence(seq, m, phys);
    } else if (authentic(n, msg, f, phys) == 0) {
        v = MRS_RX_MAC;
    } else {
        v = sequence(seq, m, phys);
    }
    return v;
}

/* The checks of RxLink.accept after the ID, in its order; phys gets the frame's physical values
 * (valid when the verdict is ACCEPTED). */
static mrs_rx_verdict_t check(mrs_node_t *n, int msg, mrs_e2e_receiver_t *seq, const mrs_frame_t *f, double *phys)
{
    const mrs_msg_t *m = &mrs_messages[msg];
    mrs_rx_verdict_t v = MRS_RX_ACCEPTED;
    if (f->len != m->length) {
        v = MRS_RX_LENGTH;
    } else if ((m->e2e != 0u) && (f->data[m->crc_byte] != mrs_e2e_crc(m->data_id, f->data, f->len, m->crc_byte))) {
        v = MRS_RX_CRC;
    } else if (m->unpack(phys, f->data, f->len) != 0) {
        v = MRS_RX_LENGTH;
    } else {
        v = check_decoded(n, msg, seq, f, phys);
    }
    return v;
}

/* A sensor input's verdict into its receive state (inputs.py): its rejects and cause, or its
 * value, alive counter, age 0 and seen. */
static void store(mrs_node_t *n, mrs_input_t *in, mrs_rx_verdict_t v, const double *phys, double stamp)
{
    if (v != MRS_RX_ACCEPTED) {
        ++n->stats.rx_rejected;
        if (v == MRS_RX_MAC) {
            if (n->verifier.have_current != 0) {
                ++n->stats.rx_auth_failed;
            } else {
                ++n->stats.rx_unsynced; /* no epoch to verify against yet (stats.py) */
            }
        }
        ++in->rejects;
        in->bad_cause = cause_of(v);
    } else {
        int j;
        in->rejects = 0;
        in->value = phys[in->sig];
        for (j = 0; j < MRS_INPUT_EXTRA; ++j) {
            if (in->extra_sig[j] >= 0) {
                in->extra[j] = phys[in->extra_sig[j]];
            }
        }
        in->last_counter = (unsigned)phys[mrs_messages[in->msg].counter];
        in->age = 0;
        in->seen = 1;
        if (in->msg == MRS_MSG_REDUNDANT) {
            mrs_node_time_redundant(n, in->last_counter);
            mrs_node_keep_redundant_angle(n);
        }
        if (in->msg == MRS_MSG_YAW) {
            n->yaw_stamp = stamp;
            mrs_node_count_yaw(n, in->last_counter);
        }
    }
}

mrs_rx_verdict_t mrs_node_accept(mrs_node_t *n, const mrs_frame_t *f)
{
    double phys[MRS_MAX_SIGNALS];
    mrs_input_t *in = NULL;
    mrs_rx_verdict_t v = MRS_RX_IGNORED;
    int is_sync = 0;
    int i;
    if ((n->keyed != 0) && (f->id == mrs_messages[MRS_MSG_SYNC].frame_id)) {
        is_sync = 1;
    }
    for (i = 0; i < MRS_N_INPUTS; ++i) {
        if (f->id == mrs_messages[n->in[i].msg].frame_id) {
            in = &n->in[i];
        }
    }
    if (((in == NULL) && (is_sync == 0)) || ((f->flags & MRS_FRAME_EXTENDED) != 0u)) {
        v = MRS_RX_IGNORED; /* outside the receive filters: never reaches the node, as with python-can */
    } else if ((f->flags & (MRS_FRAME_REMOTE | MRS_FRAME_ERROR)) != 0u) {
        ++n->stats.rx_frames;
        ++n->stats.rx_ignored;
        v = MRS_RX_IGNORED;
    } else if (is_sync != 0) {
        ++n->stats.rx_frames;
        v = check(n, MRS_MSG_SYNC, NULL, f, phys);
        if (v != MRS_RX_ACCEPTED) {
            ++n->stats.syncs_rejected;
        } else {
            n->sync_age = 0;
            mrs_sensor_adopt(&n->verifier, n->signer.epoch);
        }
    } else {
        ++n->stats.rx_frames;
        v = check(n, in->msg, &in->seq, f, phys);
        store(n, in, v, phys, f->stamp);
    }
    return v;
}

int mrs_node_receive(mrs_node_t *n, const mrs_frame_t *f)
{
    const mrs_rx_verdict_t v = mrs_node_accept(n, f);
    return ((v == MRS_RX_ACCEPTED) && (f->id == mrs_messages[MRS_MSG_YAW].frame_id)) ? 1 : 0;
}
