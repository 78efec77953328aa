/*
 * One controller on one bus, C99 port of firmware_py/controller/node.py (ControllerNode): the
 * receive chain of mrsteer_dbc.link.RxLink (length -> CRC -> counter value -> range -> MAC ->
 * counter sequence), each input's freshness, one control cycle per period on the fresh inputs
 * (mrs_cycle_step: the plausibility monitor, mrs_step() held on the monitor's suspicion of the
 * yaw rate, the authority limiter; firmware_py.cycle), and the command and status frames of
 * mrsteer_dbc.link.TxLink (alive counter, SecOC fields and MAC when keyed, CRC last).
 * Frames are packed and unpacked only through mrs_contract.c, i.e. the cantools-generated codec.
 */
#ifndef MRS_NODE_CORE_H
#define MRS_NODE_CORE_H

#include <stdint.h>

#include "mrs_bus.h"
#include "mrs_controller.h"
#include "mrs_cycle.h"
#include "mrs_e2e.h"
#include "mrs_monitor.h"
#include "mrs_secoc.h"

#define MRS_LATENESS_BINS 50000u /* 1 us bins up to 50 ms; one more for the overflow */
#define MRS_SYNC_STALE_CYCLES 3 /* MRS_SecOCSync cycle times without a valid sync before CAUSE_AUTH */
/* The longest the start state lasts, from the first period (node.py's START_TIMEOUT_S). */
#define MRS_START_TIMEOUT_S 10.0
#define MRS_N_INPUTS 4 /* driver angle, yaw rate, speed, the redundant sensors */
#define MRS_IN_REDUNDANT 3 /* its index in mrs_node_t.in */
/* Yaw-rate samples (the monitor's steps) a redundant sample's arrival may differ from its alive
 * counter's account of the time before it is withheld from the monitor
 * (firmware_py/controller/sample_clock.py's REDUNDANT_JITTER_CYCLES). */
#define MRS_REDUNDANT_JITTER_CYCLES 2

/* The most further measurements one sensor message carries (MRS_RedundantSensors: two). */
#define MRS_INPUT_EXTRA 2

/* Receive state of one sensor input (firmware_py/controller/inputs.py). */
typedef struct {
    int msg; /* MRS_MSG_* */
    int sig; /* its measurement signal */
    /* further measurement signals of the same frame, -1 if none: the yaw rate's second element;
     * the redundant frame's second steering channel and second speed */
    int extra_sig[MRS_INPUT_EXTRA];
    unsigned missing_cause; /* 0: an invalid input adds no cause bit (the redundant sensors) */
    double value, extra[MRS_INPUT_EXTRA]; /* NaN until received */
    long age, limit;
    int rejects;
    int seen; /* a frame of it was accepted since power-up (the start state waits for each input's first) */
    unsigned last_counter, bad_cause;
    mrs_e2e_receiver_t seq;
} mrs_input_t;

typedef struct {
    uint32_t counts[MRS_LATENESS_BINS + 1u];
    uint64_t n;
    double max;
} mrs_lateness_t;

typedef struct {
    uint64_t cycles, overruns, missed_cycles, rx_frames, rx_rejected, rx_ignored, syncs_rejected, rx_auth_failed,
        rx_unsynced, tx_frames, cmd_withheld, faults_entered;
    mrs_lateness_t lateness;
    long rss_kb_loop_start, rss_kb_loop_end;
} mrs_stats_t;

typedef struct {
    double rate_hz;
    int timeout_cycles; /* per input, in units of that input's DBC cycle time */
    int e2e_fail_max; /* consecutive rejected frames of one input that fault it at once */
    int max_counter_delta;
    const uint8_t *secoc_key; /* NULL: no SecOC */
    mrs_config_t controller; /* ts, input ranges and aux_limit are set from the rate and the DBC */
} mrs_node_config_t;

typedef struct {
    mrs_bus_t *bus;
    double period;
    int e2e_fail_max;
    mrs_cycle_coeffs_t cycle_c; /* the law's, the monitor's and the limiter's coefficients */
    /* the three states, the command sent last (cycle_s.command), the monitor's bits of its latest
     * step (cycle_s.plausibility) and the state sent last (cycle_s.reported, mrs_reported_state()) */
    mrs_cycle_state_t cycle_s;
    mrs_input_t in[MRS_N_INPUTS]; /* driver angle, yaw rate, speed, redundant (lat. accel., 2nd steering) */
    double red_expected; /* control periods per redundant sample (its DBC cycle) */
    long red_cycles; /* monitor steps (yaw-rate samples) since the last accepted redundant frame */
    int red_counter; /* its alive counter; -1 before the first */
    int red_usable; /* the held redundant sample arrived in time (SampleClock.redundant_in_time) */
    double steer_at_red; /* the driver's angle when the newest redundant frame arrived (node.py) */
    int red_unstepped; /* the monitor has yet to step over that redundant sample */
    int yaw_counter; /* alive counter of the newest accepted yaw-rate frame; -1 before the first */
    long yaw_samples; /* yaw-rate samples since the last period, by that counter */
    int starting; /* the start state (node.py's _still_starting) */
    long since_first; /* periods since the one that drained the first sensor frame; -1: none yet */
    long start_limit; /* MRS_START_TIMEOUT_S in periods */
    double rejected_wrap, overruns_wrap, lateness_max; /* the status's counters' DBC widths, lateness's max */
    int keyed;
    mrs_cmac_t *cmac;
    mrs_signer_t signer;
    mrs_sensor_verifier_t verifier;
    long sync_age, sync_limit;
    uint64_t status_every;
    uint8_t cmd_alive;
    unsigned cause, answers;
    double max_lateness, yaw_stamp;
    int was_fault;
    mrs_stats_t stats;
} mrs_node_t;

/* 0, or -1 with the reason in err (an impossible calibration, no OpenSSL CMAC). */
int mrs_node_init(mrs_node_t *n, mrs_bus_t *bus, const mrs_node_config_t *cfg, char *err, size_t err_len);
void mrs_node_free(mrs_node_t *n);

/* ---- The receive chain (mrs_node_rx.c): the only path a received frame takes. ---- */

/* A frame's verdict: accepted, or the first check that refused it (mrsteer_dbc.link.Rejected,
 * in its order). */
typedef enum {
    MRS_RX_ACCEPTED = 0,
    MRS_RX_IGNORED = 1, /* not the node's: another ID, an extended ID, a remote or error frame */
    MRS_RX_LENGTH = 2,
    MRS_RX_CRC = 3,
    MRS_RX_COUNTER_VALUE = 4,
    MRS_RX_RANGE = 5,
    MRS_RX_MAC = 6,
    MRS_RX_REPEATED = 7,
    MRS_RX_WRONG_SEQUENCE = 8
} mrs_rx_verdict_t;

/* The IDs the node receives (its receive filters); returns how many. */
size_t mrs_node_filter_ids(int keyed, uint32_t ids[8]);

/* Check one frame through the whole chain and store it (the input's value, counter and age, or
 * its rejects and cause; a sync's epoch): the verdict. */
mrs_rx_verdict_t mrs_node_accept(mrs_node_t *n, const mrs_frame_t *f);

/* mrs_node_accept: 1 if it was an accepted yaw-rate frame, else 0. */
int mrs_node_receive(mrs_node_t *n, const mrs_frame_t *f);

/* The redundant sample's timing and the yaw-rate sample count (mrs_node_core.c: the monitor's
 * clock), for the receive chain on each accepted frame of that message. */
void mrs_node_time_redundant(mrs_node_t *n, unsigned counter);
/* The driver's angle held when a redundant frame is accepted (NaN when that input is not valid),
 * for the monitor's first step after it (mrs_node_core.c; node.py's monitor_driver_angle). */
void mrs_node_keep_redundant_angle(mrs_node_t *n);
void mrs_node_count_yaw(mrs_node_t *n, unsigned counter);

/* Freshness, one control cycle (mrs_cycle_step), causes, command (and status at its cycle), as
 * ControllerNode.control: 0, or -1 when the bus failed. */
int mrs_node_control(mrs_node_t *n);

/* The next frame of message msg (MRS_MSG_CMD or MRS_MSG_STATUS) from its physical values: alive
 * counter, SecOC fields and MAC when keyed and synced, E2E CRC last (TxLink.payload). Its length,
 * or -1. */
int mrs_node_build_frame(mrs_node_t *n, int msg, double *phys, uint8_t data[8]);

/* The final zero command marked INACTIVE, as on an orderly shutdown. */
int mrs_node_finish(mrs_node_t *n);

void mrs_lateness_add(mrs_lateness_t *h, double late);
double mrs_lateness_percentile(const mrs_lateness_t *h, double q);

#endif
