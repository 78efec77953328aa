/*
 * mrs_node: the C controller process, the counterpart of `mrsteer controller`
 * (firmware_py/controller/main.py and node.py's loops): the same flags where they apply, the
 * same ready line, the same --stats-out fields, the same exit statuses (2 for a usage error, 1
 * when the bus cannot be opened or fails). `mrs_node --help` lists the flags; docs/porting.md
 * describes the node.
 *
 * Two triggers. clock: absolute deadlines on CLOCK_MONOTONIC (clock_nanosleep TIMER_ABSTIME),
 * overruns counted, the grid phase-locked to the yaw-rate frames' bus stamps (timing.py);
 * sensors: one cycle per accepted yaw-rate frame (lockstep), a watchdog cycle after
 * max(yaw timeout, 1 s) without one. SIGINT/SIGTERM end the loop after the current cycle with a
 * final zero command marked INACTIVE and exit status 0.
 */
#define _GNU_SOURCE
#include <errno.h>
#include <math.h>
#include <sched.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/prctl.h>
#include <time.h>
#include <unistd.h>

#include "mrs_contract.h"
#include "mrs_node_core.h"
#include "mrs_node_opts.h"

#define SENSORS_WATCHDOG_S 1.0
#define STOP_POLL_S 0.05
#define SYNC_GAIN 0.1
#define SYNC_MAX_SLEW 0.02
#define SYNC_WINDOW 0.25

static volatile sig_atomic_t running = 1;

static void on_signal(int sig)
{
    (void)sig;
    running = 0;
}

static double mono(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + (double)t.tv_nsec * 1e-9;
}

static double wall(void)
{
    struct timespec t;
    clock_gettime(CLOCK_REALTIME, &t);
    return (double)t.tv_sec + (double)t.tv_nsec * 1e-9;
}

static void sleep_until(double deadline)
{
    struct timespec t;
    t.tv_sec = (time_t)deadline;
    t.tv_nsec = (long)((deadline - (double)t.tv_sec) * 1e9);
    if (t.tv_nsec >= 1000000000L) {
        ++t.tv_sec;
        t.tv_nsec -= 1000000000L;
    }
    /* Resumed after a signal: the cycle still runs, the loop ends after it. */
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &t, NULL) == EINTR) {
    }
}

/* Shift of the next deadline toward arrival + offset (timing.py phase_correction). */
static double phase_correction(double arrival, double cycle_start, double period, double offset)
{
    double err = arrival + offset - cycle_start;
    const double limit = SYNC_MAX_SLEW * period;
    double c;
    err -= period * nearbyint(err / period);
    c = SYNC_GAIN * err;
    return c > limit ? limit : (c < -limit ? -limit : c);
}

/* Every frame waiting: 1 if an accepted yaw-rate frame was among them, 0 if not, -1 bus failed. */
static int drain(mrs_node_t *n)
{
    mrs_frame_t f;
    int got = 0, r;
    while ((r = n->bus->recv(n->bus, &f, 0.0)) == 1) {
        got = mrs_node_receive(n, &f) || got;
    }
    return r < 0 ? -1 : got;
}

static int run_on_clock(mrs_node_t *n, const mrs_node_opts_t *o, double end)
{
    const double period = n->period * o->slow_motion, window = SYNC_WINDOW * period;
    const double epoch_to_mono = mono() - wall();
    double deadline = mono();
    while (running) {
        double now = mono(), late;
        int got;
        if (now < deadline) {
            sleep_until(deadline);
            now = mono();
        }
        late = now - deadline;
        mrs_lateness_add(&n->stats.lateness, late);
        if (late > n->max_lateness) {
            n->max_lateness = late;
        }
        if (late >= period) { /* whole periods were lost: count them and restart the grid from now */
            const double missed = floor(late / period);
            ++n->stats.overruns;
            n->stats.missed_cycles += (uint64_t)missed;
            deadline += missed * period;
        }
        if ((got = drain(n)) < 0) {
            return -1;
        }
        if (o->sync && !got) { /* this period's frame is late: a bounded window, not a whole period */
            const double until = now + window;
            double left;
            mrs_frame_t f;
            while (!got && (left = until - mono()) > 0.0) {
                const int r = n->bus->recv(n->bus, &f, left);
                if (r < 0) {
                    return -1;
                }
                if (r == 1) {
                    got = mrs_node_receive(n, &f);
                }
            }
        }
        if (mrs_node_control(n) != 0) {
            return -1;
        }
        deadline += period;
        if (o->sync && got && n->yaw_stamp > 0.0) {
            deadline += phase_correction(n->yaw_stamp + epoch_to_mono, now, period, o->sync_offset);
        }
        if (end > 0.0 && now >= end) {
            break;
        }
    }
    return 0;
}

/* The next frame within wait s, waited for in slices so that a stop is seen promptly:
 * 1 with a frame, 0 without (or stopped), -1 bus failed. */
static int recv_unless_stopped(mrs_node_t *n, mrs_frame_t *f, double wait)
{
    const double until = mono() + wait;
    while (running) {
        const double left = until - mono();
        int r;
        if (left <= 0.0) {
            return 0;
        }
        r = n->bus->recv(n->bus, f, left < STOP_POLL_S ? left : STOP_POLL_S);
        if (r != 0) {
            return r;
        }
    }
    return 0;
}

static int run_on_sensors(mrs_node_t *n, const mrs_node_opts_t *o, double end)
{
    /* Simulated time is the plant's: a plant that is merely slow must not look like lost input. */
    double wait = (double)n->in[1].limit * n->period * o->slow_motion;
    if (wait < SENSORS_WATCHDOG_S) {
        wait = SENSORS_WATCHDOG_S;
    }
    while (running) {
        mrs_frame_t f;
        int got = 0, more;
        const int r = recv_unless_stopped(n, &f, wait);
        if (r < 0) {
            return -1;
        }
        if (!running) {
            break; /* stopped while waiting: no cycle on a frame or a watchdog that ended the run */
        }
        if (r == 1) {
            got = mrs_node_receive(n, &f);
        }
        if ((more = drain(n)) < 0) {
            return -1;
        }
        got = more || got;
        if ((got || r == 0) && mrs_node_control(n) != 0) {
            return -1;
        }
        if (end > 0.0 && mono() >= end) {
            break;
        }
    }
    return 0;
}

static long rss_kb(void)
{
    long pages = 0, rss = 0;
    FILE *f = fopen("/proc/self/statm", "r");
    if (f == NULL) {
        return 0;
    }
    if (fscanf(f, "%ld %ld", &pages, &rss) != 2) {
        rss = 0;
    }
    fclose(f);
    return rss * (sysconf(_SC_PAGESIZE) / 1024);
}

/* SCHED_FIFO and CPU pinning where permitted; what happened goes into the stats' platform part. */
static void apply_platform(const mrs_node_opts_t *o, char *platform, size_t len)
{
    char denied[400] = "";
    cpu_set_t set;
    size_t used;
    int applied = 0, i, first = 1;
    if (o->rt_priority > 0) {
        struct sched_param p;
        p.sched_priority = o->rt_priority;
        if (sched_setscheduler(0, SCHED_FIFO, &p) == 0) {
            applied = o->rt_priority;
        } else {
            snprintf(denied, sizeof denied, ", \"rt_priority_denied\": \"[Errno %d] %s\"", errno, strerror(errno));
        }
    }
    if (o->cpu >= 0) {
        CPU_ZERO(&set);
        CPU_SET(o->cpu, &set);
        if (sched_setaffinity(0, sizeof set, &set) != 0) {
            const size_t k = strlen(denied);
            snprintf(denied + k, sizeof denied - k, ", \"cpu_denied\": \"[Errno %d] %s\"", errno, strerror(errno));
        }
    }
    used = (size_t)snprintf(platform, len, "\"rt_priority\": %d%s, \"cpu_affinity\": [", applied, denied);
    CPU_ZERO(&set);
    if (sched_getaffinity(0, sizeof set, &set) == 0) {
        for (i = 0; i < CPU_SETSIZE && used < len; ++i) {
            if (CPU_ISSET(i, &set)) {
                used += (size_t)snprintf(platform + used, len - used, "%s%d", first ? "" : ", ", i);
                first = 0;
            }
        }
    }
    if (used < len) {
        snprintf(platform + used, len - used, "], \"gc_disabled_in_loop\": false");
    }
}

/* --stats-out, written whole (a temporary file renamed over it). */
static int write_stats(const char *path, const mrs_node_t *n, const char *platform)
{
    const mrs_stats_t *s = &n->stats;
    char tmp[4200];
    FILE *f;
    snprintf(tmp, sizeof tmp, "%s.tmp-%ld", path, (long)getpid());
    f = fopen(tmp, "w");
    if (f == NULL) {
        return -1;
    }
    fprintf(f, "{\n  \"cycles\": %llu, \"overruns\": %llu, \"missed_cycles\": %llu,\n"
            "  \"rx_frames\": %llu, \"rx_rejected\": %llu, \"rx_ignored\": %llu,\n"
            "  \"syncs_rejected\": %llu, \"rx_auth_failed\": %llu, \"rx_unsynced\": %llu, \"tx_frames\": %llu,\n"
            "  \"cmd_withheld\": %llu, \"faults_entered\": %llu,\n"
            "  \"lateness_p50_s\": %.17g, \"lateness_p99_s\": %.17g, \"lateness_max_s\": %.17g,\n"
            "  \"rss_kb_loop_start\": %ld, \"rss_kb_loop_end\": %ld, \"rss_kb_growth\": %ld,\n"
            "  \"implementation\": \"c\", %s\n}\n",
            (unsigned long long)s->cycles, (unsigned long long)s->overruns, (unsigned long long)s->missed_cycles,
            (unsigned long long)s->rx_frames, (unsigned long long)s->rx_rejected, (unsigned long long)s->rx_ignored,
            (unsigned long long)s->syncs_rejected, (unsigned long long)s->rx_auth_failed,
            (unsigned long long)s->rx_unsynced, (unsigned long long)s->tx_frames, (unsigned long long)s->cmd_withheld,
            (unsigned long long)s->faults_entered,
            mrs_lateness_percentile(&s->lateness, 0.5), mrs_lateness_percentile(&s->lateness, 0.99), s->lateness.max,
            s->rss_kb_loop_start, s->rss_kb_loop_end, s->rss_kb_loop_end - s->rss_kb_loop_start, platform);
    if (fclose(f) != 0 || rename(tmp, path) != 0) {
        remove(tmp);
        return -1;
    }
    return 0;
}

static int open_bus(mrs_bus_t *bus, const mrs_node_opts_t *o, int keyed)
{
    uint32_t ids[8];
    char err[512];
    const size_t n_ids = mrs_node_filter_ids(keyed, ids);
    const int r = o->socketcan ? mrs_bus_open_socketcan(bus, o->channel, ids, n_ids, err, sizeof err)
                               : mrs_bus_open_fallback(bus, o->channel, ids, n_ids, err, sizeof err);
    if (r != 0) {
        fprintf(stderr, "%s: error: %s\n", MRS_NODE_PROG, err);
    }
    return r;
}

int main(int argc, char **argv)
{
    static mrs_node_t node; /* the lateness histogram: 200 kB, not on the stack */
    mrs_node_opts_t o;
    mrs_node_config_t cfg;
    mrs_bus_t bus;
    struct sigaction sa;
    char err[512], platform[1024], slow[48] = "";
    int code = 0, r;
    const int parsed = mrs_node_parse(argc, argv, &o, &cfg);
    if (parsed >= 0) {
        return parsed; /* --help (0) or a usage error (2), already said */
    }
    if (open_bus(&bus, &o, cfg.secoc_key != NULL) != 0) {
        return 2; /* every error is exit status 2, as in Python */
    }
    if (mrs_node_init(&node, &bus, &cfg, err, sizeof err) != 0) {
        fprintf(stderr, "%s: error: %s\n", MRS_NODE_PROG, err);
        bus.close(&bus);
        return 2;
    }
    apply_platform(&o, platform, sizeof platform);
    /* Linux delays a normal task's timed sleep by up to its timer slack (50 us by default): a
     * deadline loop wants it as small as the kernel allows. */
    (void)prctl(PR_SET_TIMERSLACK, 1UL, 0UL, 0UL, 0UL);
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal; /* no SA_RESTART: a blocking wait returns on the signal */
    sigaction(SIGTERM, &sa, NULL);
    sigaction(SIGINT, &sa, NULL);
    if (o.slow_motion != 1.0) {
        snprintf(slow, sizeof slow, " in %gx slow motion", o.slow_motion);
    }
    fprintf(stderr, "%s: running at %g Hz%s (%s trigger%s) on %s\n", MRS_NODE_PROG, o.rate_hz, slow,
            o.sensors_trigger ? "sensors" : "clock",
            cfg.secoc_key != NULL ? ", commands and sensor frames authenticated (SecOC)" : "", bus.info);
    node.stats.rss_kb_loop_start = rss_kb();
    {
        const double end = o.duration > 0.0 ? mono() + o.duration : 0.0;
        r = o.sensors_trigger ? run_on_sensors(&node, &o, end) : run_on_clock(&node, &o, end);
    }
    node.stats.rss_kb_loop_end = rss_kb();
    if (r != 0) {
        fprintf(stderr, "%s: error: bus failed: %s\n", MRS_NODE_PROG, bus.error);
        code = 2;
    } else {
        (void)mrs_node_finish(&node); /* the bus may already be gone: nothing more to say on it */
    }
    bus.close(&bus);
    mrs_node_free(&node);
    if (o.stats_out != NULL && write_stats(o.stats_out, &node, platform) != 0) {
        fprintf(stderr, "%s: error: cannot write %s: %s\n", MRS_NODE_PROG, o.stats_out, strerror(errno));
        code = 2;
    }
    return code;
}
