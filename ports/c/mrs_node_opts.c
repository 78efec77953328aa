/* The command line of mrs_node: see mrs_node_opts.h. */
#include "mrs_node_opts.h"

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "mrs_config.h"
#include "mrs_defaults.h" /* PAPER_K, PAPER_TAU, DEFAULT_TAU_N of firmware_py/calibration.py */

#define DEFAULT_SYNC_OFFSET_US 50.0

static const char USAGE[] =
    "usage: " MRS_NODE_PROG " [-h] [--interface socketcan|mrsteer] [--channel CHANNEL] [--rate-hz RATE_HZ]\n"
    "                [--trigger {clock,sensors}] [--sync-offset-us US] [--no-sync] [--timeout-cycles N]\n"
    "                [--calibration FILE] [--controller {limited,standard}] [--k K] [--tau TAU] [--tau-n TAU_N]\n"
    "                [--method {tustin,zoh}] [--model-delay M] [--rate-limit RAD_S] [--duration S]\n"
    "                [--slow-motion F] [--stats-out FILE] [--secoc | --secoc-key FILE] [--rt-priority P] [--cpu N]\n";

static const char HELP[] =
    "\nThe model-regulator controller in C on a CAN bus (SocketCAN or the mrsteer fallback bus): reads driver\n"
    "angle, yaw rate and speed, sends the auxiliary steering command; the counterpart of `mrsteer controller`.\n\n"
    "options:\n"
    "  -h, --help            show this help message and exit\n"
    "  --interface IFACE     socketcan or mrsteer (default: SocketCAN vcan0 if present, else the fallback bus)\n"
    "  --channel CHANNEL     channel for the interface (default vcan0 / mrsteer0)\n"
    "  --rate-hz RATE_HZ     control rate in Hz (default: the calibration's, 500 for the shipped one)\n"
    "  --trigger {clock,sensors}\n"
    "                        clock: fixed rate on the monotonic clock (default); sensors: one cycle per\n"
    "                        yaw-rate frame (lockstep)\n"
    "  --sync-offset-us US   clock trigger: start each cycle this long after the yaw-rate frame (default 50)\n"
    "  --no-sync             clock trigger: free-running grid, no phase lock\n"
    "  --timeout-cycles N    an input missing for more than N of its own cycle times is a fault (default 10)\n"
    "  --calibration FILE    calibration file (key = value lines, docs/porting.md; default: the shipped\n"
    "                        speed-scheduled calibration)\n"
    "  --controller {limited,standard}\n"
    "                        Q filter: limited (eq. 22, default) or standard (eq. 17)\n"
    "  --k K, --tau TAU, --tau-n TAU_N\n"
    "                        the paper's plain law with constant eq. (22) gain and time constant and eq. (18)\n"
    "                        time constant (the ones not given: 10, 0.006, 0.02)\n"
    "  --method {tustin,zoh}\n"
    "  --model-delay M       command delay modelled in the controller (default: the calibration's; 0 when\n"
    "                        --k, --tau or --tau-n is given)\n"
    "  --rate-limit RAD_S    command rate limit in rad/s (default: the calibration's, 0: off)\n"
    "  --duration S          stop after S seconds (wall time)\n"
    "  --slow-motion F       run F times slower than real time, for machines too slow for the loop: each period\n"
    "                        lasts F times its step in wall time; the step, every count in cycles and every\n"
    "                        result are unchanged (default 1, at most 100)\n"
    "  --stats-out FILE      write loop statistics as JSON here on exit\n"
    "  --secoc               authenticate the commands and the sensor frames with the key in $MRSTEER_SECOC_KEY\n"
    "  --secoc-key FILE      as --secoc, with the key read from FILE (32 hex digits)\n"
    "  --rt-priority P       run under SCHED_FIFO at priority P (1..99) where permitted (default 0)\n"
    "  --cpu N               pin the process to CPU N where permitted\n";

static int usage_error(const char *fmt, ...)
{
    va_list ap;
    fprintf(stderr, "%s: error: ", MRS_NODE_PROG);
    va_start(ap, fmt);
    vfprintf(stderr, fmt, ap);
    va_end(ap);
    fputc('\n', stderr);
    return 2;
}

static int real(const char *flag, const char *text, double *out)
{
    char *end;
    errno = 0;
    *out = strtod(text, &end);
    if (end == text || *end != '\0' || errno == ERANGE) {
        return usage_error("argument %s: invalid float value: '%s'", flag, text);
    }
    return 0;
}

static int whole(const char *flag, const char *text, int *out)
{
    char *end;
    long x;
    errno = 0;
    x = strtol(text, &end, 10);
    if (end == text || *end != '\0' || errno == ERANGE || x < -1000000L || x > 1000000L) {
        return usage_error("argument %s: invalid int value: '%s'", flag, text);
    }
    *out = (int)x;
    return 0;
}

static int check_output_file(const char *flag, const char *path)
{
    struct stat st;
    char parent[4096];
    const char *slash = strrchr(path, '/');
    if (stat(path, &st) == 0 && S_ISDIR(st.st_mode)) {
        return usage_error("%s %s is a directory", flag, path);
    }
    if (slash == NULL) {
        snprintf(parent, sizeof parent, ".");
    } else {
        snprintf(parent, sizeof parent, "%.*s", (int)(slash - path == 0 ? 1 : slash - path), path);
    }
    if (stat(parent, &st) != 0 || !S_ISDIR(st.st_mode)) {
        return usage_error("%s %s: %s is not an existing directory", flag, path, parent);
    }
    if (access(parent, W_OK) != 0) {
        return usage_error("%s %s: directory %s is not writable", flag, path, parent);
    }
    return 0;
}

typedef struct {
    const char *interface, *calibration, *secoc_key, *q_form, *method, *trigger;
    int secoc, have_rate, have_rate_limit, have_k, have_tau, have_tau_n, model_delay, timeout_cycles;
    double k, tau, tau_n, rate_limit, sync_offset_us;
} raw_args_t;

/* One flag (and its value, which *i moves past): 0, 1 for --help, 2 for an error. */
static int one(int argc, char **argv, int *i, raw_args_t *a, mrs_node_opts_t *o)
{
    const char *flag = argv[*i], *v = NULL;
    char name[64];
    const char *eq = strchr(flag, '=');
    static const char *const with_value[] = {
        "--interface", "--channel", "--rate-hz", "--trigger", "--sync-offset-us", "--timeout-cycles", "--calibration",
        "--controller", "--k", "--tau", "--tau-n", "--method", "--model-delay", "--rate-limit", "--duration",
        "--slow-motion", "--stats-out", "--secoc-key", "--rt-priority", "--cpu"};
    size_t j;
    int takes = 0;
    snprintf(name, sizeof name, "%.*s", eq != NULL ? (int)(eq - flag) : (int)strlen(flag), flag);
    if (strcmp(name, "-h") == 0 || strcmp(name, "--help") == 0) {
        return 1;
    }
    if (strcmp(name, "--no-sync") == 0) {
        o->sync = 0;
        return 0;
    }
    if (strcmp(name, "--secoc") == 0) {
        a->secoc = 1;
        return 0;
    }
    for (j = 0u; j < sizeof with_value / sizeof with_value[0]; ++j) {
        takes |= strcmp(name, with_value[j]) == 0;
    }
    if (!takes) {
        return usage_error("unrecognized arguments: %s", flag);
    }
    if (eq != NULL) {
        v = eq + 1;
    } else if (*i + 1 < argc) {
        v = argv[++*i];
    } else {
        return usage_error("argument %s: expected one argument", name);
    }
    if (strcmp(name, "--interface") == 0) {
        a->interface = v;
    } else if (strcmp(name, "--channel") == 0) {
        o->channel = v;
    } else if (strcmp(name, "--trigger") == 0) {
        a->trigger = v;
    } else if (strcmp(name, "--calibration") == 0) {
        a->calibration = v;
    } else if (strcmp(name, "--controller") == 0) {
        a->q_form = v;
    } else if (strcmp(name, "--method") == 0) {
        a->method = v;
    } else if (strcmp(name, "--stats-out") == 0) {
        o->stats_out = v;
    } else if (strcmp(name, "--secoc-key") == 0) {
        a->secoc_key = v;
    } else if (strcmp(name, "--rate-hz") == 0) {
        a->have_rate = 1;
        return real(name, v, &o->rate_hz);
    } else if (strcmp(name, "--sync-offset-us") == 0) {
        return real(name, v, &a->sync_offset_us);
    } else if (strcmp(name, "--k") == 0) {
        a->have_k = 1;
        return real(name, v, &a->k);
    } else if (strcmp(name, "--tau") == 0) {
        a->have_tau = 1;
        return real(name, v, &a->tau);
    } else if (strcmp(name, "--tau-n") == 0) {
        a->have_tau_n = 1;
        return real(name, v, &a->tau_n);
    } else if (strcmp(name, "--rate-limit") == 0) {
        a->have_rate_limit = 1;
        return real(name, v, &a->rate_limit);
    } else if (strcmp(name, "--duration") == 0) {
        return real(name, v, &o->duration);
    } else if (strcmp(name, "--slow-motion") == 0) {
        return real(name, v, &o->slow_motion);
    } else if (strcmp(name, "--timeout-cycles") == 0) {
        return whole(name, v, &a->timeout_cycles);
    } else if (strcmp(name, "--model-delay") == 0) {
        return whole(name, v, &a->model_delay);
    } else if (strcmp(name, "--rt-priority") == 0) {
        return whole(name, v, &o->rt_priority);
    } else {
        return whole(name, v, &o->cpu);
    }
    return 0;
}

static int choose(const char *flag, const char *v, const char *a, const char *b, int *is_b)
{
    if (strcmp(v, a) != 0 && strcmp(v, b) != 0) {
        return usage_error("argument %s: invalid choice: '%s' (choose from '%s', '%s')", flag, v, a, b);
    }
    *is_b = strcmp(v, b) == 0;
    return 0;
}

/* The law (firmware_py/controller/options.py, calibration_from_args): the calibration file or
 * the shipped one; --k, --tau, --tau-n switch to the paper's plain law with constant gains (no
 * actuator or filter in the nominal model, no modelled delay unless --model-delay says so);
 * then --controller, --method and --rate-limit over it. */
static int controller_config(raw_args_t *a, mrs_config_t *c)
{
    char err[600];
    int is_b;
    if (a->calibration != NULL) {
        if (mrs_config_load(a->calibration, c, err, sizeof err) != 0) {
            return usage_error("argument --calibration: %s", err);
        }
    } else {
        mrs_default_config(c);
    }
    if (a->have_k || a->have_tau || a->have_tau_n) {
        c->n_schedule = 0;
        c->k = a->have_k ? a->k : MRS_PAPER_K;
        c->tau = a->have_tau ? a->tau : MRS_PAPER_TAU;
        c->tau_n = a->have_tau_n ? a->tau_n : MRS_DEFAULT_TAU_N;
        c->model_actuator_tau = 0.0;
        c->model_filter_hz = 0.0;
        c->model_delay_steps = a->model_delay >= 0 ? a->model_delay : 0;
    } else if (a->model_delay >= 0) {
        c->model_delay_steps = a->model_delay;
    }
    if (a->q_form != NULL) {
        if (choose("--controller", a->q_form, "limited", "standard", &is_b) != 0) {
            return 2;
        }
        c->q_form = is_b ? MRS_Q_STANDARD : MRS_Q_LIMITED;
    }
    if (a->method != NULL) {
        if (choose("--method", a->method, "tustin", "zoh", &is_b) != 0) {
            return 2;
        }
        c->method = is_b ? MRS_ZOH : MRS_TUSTIN;
    }
    if (a->have_rate_limit) {
        c->rate_limit = a->rate_limit;
    }
    return 0;
}

/* The rate rule of firmware_py.controller.options.calibration_for_rate: hand gains run at any
 * rate; a calibration (a file, or the built-in shipped one) only at the rate it was made for.
 * (The Python controller also has plain-law tunings for 100, 200 and 1000 Hz built in; this node
 * has only the shipped 500 Hz one, docs/porting.md.) */
static int rate_rule(const raw_args_t *a, const mrs_node_opts_t *o, const mrs_config_t *c)
{
    const double own = 1.0 / c->ts;
    if (!a->have_rate || a->have_k || a->have_tau || a->have_tau_n || fabs(o->rate_hz - own) <= 1e-9 * own) {
        return 0;
    }
    return usage_error("--rate-hz %g: the %s calibration is made for %g Hz (ts %g s); give --calibration FILE "
                       "made for %g Hz (mrsteer design tune --schedule --ts %g --out FILE.cfg)", o->rate_hz,
                       a->calibration != NULL ? "--calibration file's" : "built-in", own, c->ts, o->rate_hz,
                       1.0 / o->rate_hz);
}

static int check(const raw_args_t *a, mrs_node_opts_t *o, mrs_node_config_t *cfg)
{
    const long ncpu = sysconf(_SC_NPROCESSORS_ONLN);
    mrs_config_t probe = cfg->controller;
    mrs_coeffs_t coeffs;
    if (!(isfinite(o->rate_hz) && o->rate_hz >= 1.0 && o->rate_hz <= 10000.0)) {
        return usage_error("--rate-hz must be in [1, 10000], got %g", o->rate_hz);
    }
    if (rate_rule(a, o, &cfg->controller) != 0) {
        return 2;
    }
    if (cfg->timeout_cycles < 1) {
        return usage_error("--timeout-cycles must be at least 1");
    }
    if (o->duration != 0.0 && !(isfinite(o->duration) && o->duration > 0.0)) {
        return usage_error("--duration must be positive");
    }
    if (!(isfinite(o->slow_motion) && o->slow_motion >= 1.0 && o->slow_motion <= 100.0)) {
        return usage_error("--slow-motion must be in [1, 100], got %g", o->slow_motion);
    }
    if (o->rt_priority < 0 || o->rt_priority > 99) {
        return usage_error("--rt-priority must be in 0..99, got %d", o->rt_priority);
    }
    if (o->cpu != -1 && (o->cpu < 0 || o->cpu >= ncpu)) {
        return usage_error("--cpu must be in 0..%ld, got %d", ncpu - 1, o->cpu);
    }
    probe.ts = 1.0 / o->rate_hz;
    if (a->model_delay > MRS_MAX_MODEL_DELAY || mrs_configure(&probe, &coeffs) != 0) {
        return usage_error("invalid calibration: mrs_configure refuses it (a value non-finite, non-positive or "
                           "out of range, or a model delay outside 0..%d)", MRS_MAX_MODEL_DELAY);
    }
    if (!(isfinite(a->sync_offset_us) && a->sync_offset_us >= 0.0 && a->sync_offset_us * 1e-6 < 1.0 / o->rate_hz)) {
        return usage_error("--sync-offset-us must be in [0, one period), got %g", a->sync_offset_us);
    }
    if (o->stats_out != NULL && check_output_file("--stats-out", o->stats_out) != 0) {
        return 2;
    }
    return 0;
}

/* --interface and --channel: explicit, else SocketCAN vcan0 where this kernel has it, else the
 * fallback bus; an automatic choice is said in one line (bus_open.resolve). */
static int bus_choice(const raw_args_t *a, mrs_node_opts_t *o)
{
    if (a->interface != NULL) {
        if (strcmp(a->interface, "socketcan") != 0 && strcmp(a->interface, "mrsteer") != 0) {
            return usage_error("--interface must be socketcan or mrsteer, got '%s'", a->interface);
        }
        o->socketcan = strcmp(a->interface, "socketcan") == 0;
    } else {
        char sys_path[300];
        snprintf(sys_path, sizeof sys_path, "/sys/class/net/%s", o->channel != NULL ? o->channel : "vcan0");
        o->socketcan = access(sys_path, F_OK) == 0 && (o->channel == NULL || strncmp(o->channel, "vcan", 4u) == 0);
        if (o->socketcan) {
            fprintf(stderr, "bus: SocketCAN %s\n", o->channel != NULL ? o->channel : "vcan0");
        } else {
            fprintf(stderr, "bus: no SocketCAN vcan0 here; using the mrsteer fallback bus %s\n",
                    o->channel != NULL ? o->channel : "mrsteer0");
        }
    }
    if (o->channel == NULL) {
        o->channel = o->socketcan ? "vcan0" : "mrsteer0";
    }
    return 0;
}

int mrs_node_parse(int argc, char **argv, mrs_node_opts_t *o, mrs_node_config_t *cfg)
{
    raw_args_t a;
    char err[600];
    int i, r;
    memset(o, 0, sizeof *o);
    memset(&a, 0, sizeof a);
    o->sync = 1;
    o->cpu = -1;
    o->slow_motion = 1.0;
    a.model_delay = -1;
    a.timeout_cycles = 10;
    a.sync_offset_us = DEFAULT_SYNC_OFFSET_US;
    for (i = 1; i < argc; ++i) {
        r = one(argc, argv, &i, &a, o);
        if (r == 1) {
            printf("%s%s", USAGE, HELP);
            return 0;
        }
        if (r != 0) {
            return 2;
        }
    }
    if (a.secoc && a.secoc_key != NULL) {
        return usage_error("argument --secoc-key: not allowed with argument --secoc");
    }
    if (a.trigger != NULL && choose("--trigger", a.trigger, "clock", "sensors", &o->sensors_trigger) != 0) {
        return 2;
    }
    memset(cfg, 0, sizeof *cfg);
    if (controller_config(&a, &cfg->controller) != 0) {
        return 2;
    }
    if (!a.have_rate) {
        o->rate_hz = 1.0 / cfg->controller.ts;
    }
    cfg->rate_hz = o->rate_hz;
    cfg->timeout_cycles = a.timeout_cycles;
    cfg->e2e_fail_max = 3;
    cfg->max_counter_delta = 3;
    o->sync_offset = a.sync_offset_us * 1e-6;
    if (check(&a, o, cfg) != 0) {
        return 2;
    }
    if (a.secoc || a.secoc_key != NULL) {
        if (mrs_secoc_load_key(a.secoc_key, o->key, err, sizeof err) != 0) {
            return usage_error("%s", err);
        }
        cfg->secoc_key = o->key;
    }
    return bus_choice(&a, o) != 0 ? 2 : -1;
}
