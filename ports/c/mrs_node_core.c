/* One controller on one bus: see mrs_node_core.h (its receive chain is mrs_node_rx.c). */
#include "mrs_node_core.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "mrs_contract.h"

/* `cycles` of the message's own cycle time in controller periods, rounded up (the 1e-9 keeps
 * 3 * 0.1 / 1e-3 = 300.00000000000006 at 300), at least 1: node.py's limit(). */
static long limit_cycles(const mrs_msg_t *m, double period, int cycles)
{
    const double cycle = (m->control_loop || m->cycle_s == 0.0) ? period : m->cycle_s;
    const double x = ceil((double)cycles * cycle / period - 1e-9);
    return x < 1.0 ? 1L : (long)x;
}

int mrs_node_init(mrs_node_t *n, mrs_bus_t *bus, const mrs_node_config_t *cfg, char *err, size_t err_len)
{
    static const int msgs[MRS_N_INPUTS] = {MRS_MSG_STEER, MRS_MSG_YAW, MRS_MSG_SPEED, MRS_MSG_REDUNDANT};
    static const int sigs[MRS_N_INPUTS] = {MRS_SIG_STEER_ANGLE, MRS_SIG_YAW_RATE, MRS_SIG_SPEED, MRS_SIG_LAT_ACCEL};
    static const int extras[MRS_N_INPUTS][MRS_INPUT_EXTRA] = {
        {-1, -1}, {MRS_SIG_YAW_RATE_2, -1}, {-1, -1}, {MRS_SIG_STEER_ANGLE_2, MRS_SIG_SPEED_2}};
    /* A missing redundant input is no cause: the monitor reports it (PLAUS_DEGRADED). */
    static const unsigned causes[MRS_N_INPUTS] = {MRS_CAUSE_STEER_MISSING, MRS_CAUSE_YAW_MISSING,
                                                  MRS_CAUSE_SPEED_MISSING, 0u};
    const mrs_msg_t *cmd = &mrs_messages[MRS_MSG_CMD];
    mrs_config_t ctrl = cfg->controller;
    mrs_monitor_config_t mon;
    mrs_authority_config_t auth;
    double status_cycle, every;
    int i, j, rc;
    memset(n, 0, sizeof *n);
    n->bus = bus;
    n->period = 1.0 / cfg->rate_hz;
    n->e2e_fail_max = cfg->e2e_fail_max;
    /* The firmware's input ranges are the DBC's: one source of truth for what is valid. */
    ctrl.ts = n->period;
    ctrl.driver_angle_max = mrs_messages[MRS_MSG_STEER].max[MRS_SIG_STEER_ANGLE];
    ctrl.yaw_rate_max = mrs_messages[MRS_MSG_YAW].max[MRS_SIG_YAW_RATE];
    ctrl.speed_max = mrs_messages[MRS_MSG_SPEED].max[MRS_SIG_SPEED];
    if (cmd->max[MRS_SIG_CMD_ANGLE] < ctrl.aux_limit) {
        ctrl.aux_limit = cmd->max[MRS_SIG_CMD_ANGLE];
    }
    /* The monitor's and the limiter's defaults at the node's period; the limiter's magnitude is
     * the law's effective aux_limit (the calibration's, within the DBC's). */
    mrs_monitor_default_config(&mon);
    mon.ts = n->period;
    mrs_authority_default_config(&auth);
    auth.ts = n->period;
    auth.u_max = ctrl.aux_limit;
    rc = mrs_cycle_configure(&ctrl, &mon, &auth, &n->cycle_c);
    if (rc == MRS_CYCLE_BAD_LAW) {
        snprintf(err, err_len, "invalid calibration (mrs_configure refused it: a value non-finite, non-positive "
                 "or out of range)");
        return -1;
    }
    if (rc != 0) {
        snprintf(err, err_len, "invalid plausibility monitor or authority limiter configuration at %g Hz",
                 cfg->rate_hz);
        return -1;
    }
    mrs_cycle_reset(&n->cycle_s);
    for (i = 0; i < MRS_N_INPUTS; ++i) {
        mrs_input_t *in = &n->in[i];
        in->msg = msgs[i];
        in->sig = sigs[i];
        in->missing_cause = causes[i];
        in->value = NAN;
        for (j = 0; j < MRS_INPUT_EXTRA; ++j) {
            in->extra_sig[j] = extras[i][j];
            in->extra[j] = NAN;
        }
        in->limit = limit_cycles(&mrs_messages[msgs[i]], n->period, cfg->timeout_cycles);
        in->age = in->limit + 1; /* never received: invalid until the first good frame */
        mrs_e2e_receiver_init(&in->seq, (uint8_t)cfg->max_counter_delta);
    }
    n->sync_limit = limit_cycles(&mrs_messages[MRS_MSG_SYNC], n->period, MRS_SYNC_STALE_CYCLES);
    {
        const double x = ceil(MRS_START_TIMEOUT_S / n->period - 1e-9);
        n->start_limit = x < 1.0 ? 1L : (long)x;
    }
    n->starting = 1;
    n->since_first = -1;
    {
        const mrs_msg_t *st = &mrs_messages[MRS_MSG_STATUS];
        n->rejected_wrap = st->max[MRS_SIG_STATUS_REJECTED] + 1.0;
        n->overruns_wrap = st->max[MRS_SIG_STATUS_OVERRUNS] + 1.0;
        n->lateness_max = st->max[MRS_SIG_STATUS_LATENESS];
    }
    n->sync_age = n->sync_limit + 1;
    n->keyed = cfg->secoc_key != NULL;
    if (n->keyed) {
        n->cmac = mrs_cmac_new(cfg->secoc_key);
        if (n->cmac == NULL) {
            snprintf(err, err_len, "OpenSSL has no AES-128 CMAC here");
            return -1;
        }
    }
    status_cycle = mrs_messages[MRS_MSG_STATUS].cycle_s > 0.0 ? mrs_messages[MRS_MSG_STATUS].cycle_s : 0.1;
    every = nearbyint(status_cycle / n->period); /* Python's round(): ties to even */
    n->status_every = every < 1.0 ? 1u : (uint64_t)every;
    n->cmd_alive = MRS_E2E_COUNTER_MODULO - 1u;
    n->answers = MRS_MEAS_NONE;
    {
        const mrs_msg_t *rm = &mrs_messages[MRS_MSG_REDUNDANT];
        n->red_expected = ((rm->control_loop || rm->cycle_s == 0.0) ? n->period : rm->cycle_s) / n->period;
    }
    n->red_counter = -1;
    n->steer_at_red = NAN;
    n->red_unstepped = 0;
    n->yaw_counter = -1;
    n->yaw_samples = 0;
    return 0;
}

void mrs_node_free(mrs_node_t *n)
{
    mrs_cmac_free(n->cmac);
    n->cmac = NULL;
}

/* A redundant sample is in time when it arrived within MRS_REDUNDANT_JITTER_CYCLES monitor steps of
 * what its alive counter says elapsed since the one before (the first one is): node.py's
 * SampleClock.redundant_frame (firmware_py/controller/sample_clock.py); the receive chain
 * (mrs_node_rx.c) calls it on each accepted one. */
void mrs_node_time_redundant(mrs_node_t *n, unsigned counter)
{
    /* The yaw-rate samples drained before it in this period are not yet in red_cycles (the
     * period adds its count): they belong to this interval, and not to the next. */
    const long limit = n->in[1].limit;
    const long before = n->yaw_samples < limit ? n->yaw_samples : limit;
    if (n->red_counter >= 0) {
        const unsigned delta =
            (counter + MRS_E2E_COUNTER_MODULO - (unsigned)n->red_counter) % MRS_E2E_COUNTER_MODULO;
        const double expected = (double)delta * n->red_expected;
        n->red_usable =
            fabs((double)(n->red_cycles + before) - expected) <= (double)MRS_REDUNDANT_JITTER_CYCLES;
    } else {
        n->red_usable = 1;
    }
    n->red_counter = (int)counter;
    n->red_cycles = -before;
}

/* The yaw-rate samples since the last period, by the accepted frames' alive counter (a lost
 * or rejected frame's sample counts): SampleClock.yaw_frame; the receive chain calls it on each
 * accepted yaw-rate frame. */
void mrs_node_count_yaw(mrs_node_t *n, unsigned counter)
{
    n->yaw_samples += n->yaw_counter < 0
                          ? 1L
                          : (long)((counter + MRS_E2E_COUNTER_MODULO - (unsigned)n->yaw_counter) % MRS_E2E_COUNTER_MODULO);
    n->yaw_counter = (int)counter;
}

int mrs_node_build_frame(mrs_node_t *n, int msg, double *phys, uint8_t data[8])
{
    const mrs_msg_t *m = &mrs_messages[msg];
    uint64_t fv = 0u;
    int signed_frame = 0;
    if (m->e2e) {
        n->cmd_alive = mrs_e2e_next_counter(n->cmd_alive); /* only the command is E2E among what we send */
        phys[m->counter] = (double)n->cmd_alive;
    }
    if (n->keyed && m->mac >= 0) {
        signed_frame = mrs_signer_next(&n->signer, m, phys, &fv);
    }
    if (m->pack(data, 8u, phys) != (int)m->length) {
        return -1;
    }
    if (signed_frame) {
        /* CRC and MAC are zero in data now, as the MAC wants them. */
        phys[m->mac] = (double)mrs_frame_mac(n->cmac, m->frame_id, data, m->length, fv, m->mac_bits);
        if (m->pack(data, 8u, phys) != (int)m->length) {
            return -1;
        }
    }
    if (m->e2e) {
        data[m->crc_byte] = mrs_e2e_crc(m->data_id, data, m->length, m->crc_byte);
    }
    return (int)m->length;
}

static int send_frame(mrs_node_t *n, int msg, double *phys)
{
    uint8_t data[8];
    const int len = mrs_node_build_frame(n, msg, phys, data);
    if (len < 0) {
        snprintf(n->bus->error, sizeof n->bus->error, "cannot pack %s", mrs_messages[msg].name);
        return -1;
    }
    if (n->bus->send(n->bus, mrs_messages[msg].frame_id, data, (uint8_t)len) != 0) {
        return -1;
    }
    ++n->stats.tx_frames;
    return 0;
}

static int send_command(mrs_node_t *n, double u, unsigned state)
{
    double phys[MRS_MAX_SIGNALS] = {0.0};
    if (n->keyed && (!mrs_signer_synced(&n->signer) || n->sync_age > n->sync_limit)) {
        ++n->stats.cmd_withheld; /* no fresh freshness: the actuator could not verify it (node.py) */
        return 0;
    }
    phys[MRS_SIG_CMD_STATE] = (double)state;
    phys[MRS_SIG_CMD_ANGLE] = u;
    phys[MRS_SIG_CMD_MEAS] = (double)n->answers;
    return send_frame(n, MRS_MSG_CMD, phys);
}

static int send_status(mrs_node_t *n)
{
    double phys[MRS_MAX_SIGNALS] = {0.0};
    phys[MRS_SIG_STATUS_STATE] = (double)n->cycle_s.reported;
    phys[MRS_SIG_STATUS_FLAGS] = (double)n->cycle_s.law.fault_flags;
    phys[MRS_SIG_STATUS_PLAUS] = (double)n->cycle_s.plausibility;
    phys[MRS_SIG_STATUS_CAUSE] = (double)n->cause;
    phys[MRS_SIG_STATUS_REJECTED] = (double)(n->stats.rx_rejected % (uint64_t)n->rejected_wrap);
    phys[MRS_SIG_STATUS_OVERRUNS] = (double)(n->stats.overruns % (uint64_t)n->overruns_wrap);
    phys[MRS_SIG_STATUS_LATENESS] = n->max_lateness < n->lateness_max ? n->max_lateness : n->lateness_max;
    n->max_lateness = 0.0;
    return send_frame(n, MRS_MSG_STATUS, phys);
}

/* An input is valid while its newest accepted frame is at most `limit` periods old and it has
 * not been rejected e2e_fail_max times in a row (inputs.py's Input.valid). */
static int valid(const mrs_node_t *n, const mrs_input_t *in)
{
    return in->age <= in->limit && in->rejects < n->e2e_fail_max;
}

/* The plant sends the driver's angle first in the step of a redundant sample: the angle held when
 * the redundant frame is accepted is the one sampled with it (NaN when that input is not valid:
 * a timed-out angle is no pair for it), kept for the monitor's first step after the frame. */
void mrs_node_keep_redundant_angle(mrs_node_t *n)
{
    n->steer_at_red = valid(n, &n->in[0]) ? n->in[0].value : (double)NAN;
    n->red_unstepped = 1;
}

/* valid(), then the input ages by one period. */
static int fresh(mrs_node_t *n, mrs_input_t *in)
{
    const int ok = valid(n, in);
    ++in->age;
    return ok;
}

/* Whether this period is still in the start state: some sensor input not accepted once yet, none
 * of those overdue (missing longer than its own timeout counted from the period that drained the
 * first sensor frame), and fewer than start_limit periods run: node.py's _still_starting. */
static int still_starting(mrs_node_t *n)
{
    int i, first = n->since_first >= 0, pending = 0;
    if (n->stats.cycles >= (uint64_t)n->start_limit) {
        return 0;
    }
    for (i = 0; i < MRS_N_INPUTS && !first; ++i) {
        first = n->in[i].seen;
    }
    if (first) {
        ++n->since_first;
    }
    for (i = 0; i < MRS_N_INPUTS; ++i) {
        if (!n->in[i].seen) {
            if (first && n->since_first > n->in[i].limit) {
                return 0;
            }
            pending = 1;
        }
    }
    return pending;
}

/* The driver's angle for the monitor's first step of a period of `steps`: the step that takes a
 * new redundant sample gets the angle that came with it (drained in a burst, the newest angle is
 * several samples younger, and the steering pair would read the driver's movement since as the
 * channels' disagreement), else delta_driver (node.py's monitor_driver_angle). */
static double monitor_driver(mrs_node_t *n, double delta_driver, long steps)
{
    double steer = delta_driver;
    if ((steps > 0) && n->red_unstepped) {
        n->red_unstepped = 0;
        if (!isnan(steer) && !isnan(n->steer_at_red)) {
            steer = (double)(mrs_real_t)n->steer_at_red; /* the precision of the law's inputs */
        }
    }
    return steer;
}

/* The period's inputs to the control cycle, and the cause bits of the invalid ones; the inputs
 * age by one period (node.py's control up to cycle.step). */
static unsigned period_inputs(mrs_node_t *n, mrs_cycle_inputs_t *c_in)
{
    unsigned cause = 0u;
    mrs_real_t values[3];
    int i;
    mrs_input_t *red = &n->in[MRS_IN_REDUNDANT];
    /* node.py's monitor_steps and redundant_inputs, before the ages move on: the yaw-rate
     * samples since the last period (at most its timeout; one to pause with the yaw rate
     * invalid), and the redundant sample withheld when it came off its counter's time. */
    const mrs_input_t *yaw = &n->in[1];
    const long samples = n->yaw_samples < yaw->limit ? n->yaw_samples : yaw->limit;
    const long steps = samples > 0 ? samples : (valid(n, yaw) ? 0 : 1);
    c_in->lat_accel = NAN;
    c_in->delta_driver_redundant = NAN;
    c_in->speed_redundant = NAN;
    if (fresh(n, red) && n->red_usable) {
        c_in->lat_accel = red->value;
        c_in->delta_driver_redundant = red->extra[0];
        c_in->speed_redundant = red->extra[1]; /* NaN also when the sender has none (SNA) */
    }
    n->red_cycles += samples;
    n->yaw_samples = 0;
    for (i = 0; i < 3; ++i) {
        mrs_input_t *in = &n->in[i];
        const int ok = fresh(n, in);
        if (!ok) {
            cause |= in->rejects < n->e2e_fail_max ? in->missing_cause : in->bad_cause;
        }
        values[i] = ok ? (mrs_real_t)in->value : (mrs_real_t)NAN;
    }
    /* Which measurement this command answers; NONE when no valid yaw rate went into it. */
    n->answers = isnan(values[1]) ? MRS_MEAS_NONE : n->in[1].last_counter;
    /* The monitor sees the law's three inputs at the law's precision (mrs_real_t). */
    c_in->delta_driver = (double)values[0];
    c_in->yaw_rate = (double)values[1];
    c_in->speed = (double)values[2];
    /* The yaw-rate sensor's second element comes with the first: NaN (SNA, or no valid yaw rate)
     * pauses the pair check. */
    c_in->yaw_rate_redundant = isnan(values[1]) ? (double)NAN : yaw->extra[0];
    c_in->monitor_steps = (int32_t)steps;
    c_in->monitor_driver = monitor_driver(n, c_in->delta_driver, steps);
    c_in->starting = n->starting;
    return cause;
}

int mrs_node_control(mrs_node_t *n)
{
    mrs_cycle_inputs_t c_in;
    unsigned cause, state;
    int fault;
    if (n->starting) {
        n->starting = still_starting(n);
    }
    cause = period_inputs(n, &c_in);
    /* The monitor on the yaw-rate samples (seeing the command sent last period), the law held by
     * its suspicion of the yaw rate, the limiter: the command and the state to send. */
    (void)mrs_cycle_step(&n->cycle_c, &n->cycle_s, &c_in);
    if (n->cycle_s.law.fault_flags && !cause) {
        cause |= MRS_CAUSE_RANGE;
    }
    if (n->cycle_s.law.status == MRS_STATUS_INACTIVE && !cause) {
        cause |= MRS_CAUSE_LOW_SPEED;
    }
    if (n->keyed) {
        ++n->sync_age;
        if (n->sync_age > n->sync_limit || !mrs_signer_synced(&n->signer)) {
            cause |= MRS_CAUSE_AUTH;
        }
    }
    if (n->cycle_s.plausibility & MRS_PLAUS_FAULT) {
        cause |= MRS_CAUSE_PLAUSIBILITY;
    }
    state = n->cycle_s.reported;
    fault = state == MRS_STATUS_FAULT;
    if (fault && !n->was_fault) {
        ++n->stats.faults_entered;
    }
    n->was_fault = fault;
    n->cause = cause;
    if (send_command(n, n->cycle_s.command, state) != 0) {
        return -1;
    }
    ++n->stats.cycles;
    if (n->stats.cycles % n->status_every == 0u) {
        return send_status(n);
    }
    return 0;
}

int mrs_node_finish(mrs_node_t *n)
{
    return send_command(n, 0.0, MRS_STATUS_INACTIVE);
}

void mrs_lateness_add(mrs_lateness_t *h, double late)
{
    const double bin = late > 0.0 ? late / 1e-6 : 0.0;
    const uint32_t i = bin < (double)MRS_LATENESS_BINS ? (uint32_t)bin : MRS_LATENESS_BINS;
    ++h->counts[i];
    ++h->n;
    if (late > h->max) {
        h->max = late;
    }
}

double mrs_lateness_percentile(const mrs_lateness_t *h, double q)
{
    double rank_f;
    uint64_t rank, seen = 0u;
    uint32_t i;
    if (h->n == 0u) {
        return 0.0;
    }
    rank_f = ceil(q * (double)h->n);
    rank = rank_f < 1.0 ? 1u : (uint64_t)rank_f;
    if (rank > h->n) {
        rank = h->n;
    }
    for (i = 0u; i <= MRS_LATENESS_BINS; ++i) {
        seen += h->counts[i];
        if (seen >= rank) {
            const double edge = (double)(i + 1u) * 1e-6;
            return i == MRS_LATENESS_BINS ? h->max : (edge < h->max ? edge : h->max);
        }
    }
    return h->max;
}
