/* Calibration file reader (mrs_config.h). */
#include "mrs_config.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MRS_CFG_LINE_MAX 4096

typedef struct {
    const char *key;
    double *value;
} real_key_t;

static void trim(char *s)
{
    size_t n = strlen(s);
    while (n > 0u && (s[n - 1u] == '\n' || s[n - 1u] == '\r' || s[n - 1u] == ' ' || s[n - 1u] == '\t')) {
        s[--n] = '\0';
    }
}

/* One number, the whole of text; "none" is NaN (an unset constant gain). */
static int parse_real(const char *text, double *out)
{
    char *end;
    if (strcmp(text, "none") == 0) {
        *out = NAN;
        return 0;
    }
    *out = strtod(text, &end);
    while (*end == ' ') {
        ++end;
    }
    return (end == text || *end != '\0') ? -1 : 0;
}

/* A comma-separated table into out[MRS_MAX_SCHEDULE]; *n its length (0 for an empty value). */
static int parse_table(const char *text, double *out, int *n)
{
    const char *p = text;
    *n = 0;
    while (*p == ' ') {
        ++p;
    }
    if (*p == '\0') {
        return 0;
    }
    for (;;) {
        char *end;
        if (*n >= MRS_MAX_SCHEDULE) {
            return -1;
        }
        out[*n] = strtod(p, &end);
        if (end == p) {
            return -1;
        }
        ++*n;
        while (*end == ' ') {
            ++end;
        }
        if (*end == '\0') {
            return 0;
        }
        if (*end != ',') {
            return -1;
        }
        p = end + 1;
    }
}

static int set_key(mrs_config_t *g, const char *key, const char *val, int table_len[4])
{
    const real_key_t reals[] = {
        {"k", &g->k}, {"tau", &g->tau}, {"tau_n", &g->tau_n}, {"model_actuator_tau", &g->model_actuator_tau},
        {"model_filter_hz", &g->model_filter_hz}, {"ts", &g->ts}, {"aux_limit", &g->aux_limit},
        {"rate_limit", &g->rate_limit}, {"fade_rate", &g->fade_rate}, {"speed_active_min", &g->speed_active_min},
        {"speed_max", &g->speed_max}, {"driver_angle_max", &g->driver_angle_max},
        {"yaw_rate_max", &g->yaw_rate_max}, {"nominal_l_f", &g->nominal_l_f}, {"nominal_l_r", &g->nominal_l_r},
        {"nominal_mass", &g->nominal_mass}, {"nominal_c_f", &g->nominal_c_f}, {"nominal_c_r", &g->nominal_c_r}};
    const char *tables[4] = {"schedule_speed", "schedule_k", "schedule_tau", "schedule_tau_n"};
    double *table_out[4] = {g->schedule_speed, g->schedule_k, g->schedule_tau, g->schedule_tau_n};
    unsigned i;
    if (strcmp(key, "q_form") == 0) {
        if (strcmp(val, "limited") == 0) {
            g->q_form = MRS_Q_LIMITED;
        } else if (strcmp(val, "standard") == 0) {
            g->q_form = MRS_Q_STANDARD;
        } else {
            return -1;
        }
        return 0;
    }
    if (strcmp(key, "method") == 0) {
        if (strcmp(val, "tustin") == 0) {
            g->method = MRS_TUSTIN;
        } else if (strcmp(val, "zoh") == 0) {
            g->method = MRS_ZOH;
        } else {
            return -1;
        }
        return 0;
    }
    if (strcmp(key, "model_delay_steps") == 0) {
        char *end;
        const long m = strtol(val, &end, 10);
        if (end == val || *end != '\0' || m < 0 || m > MRS_MAX_MODEL_DELAY) {
            return -1;
        }
        g->model_delay_steps = (int)m;
        return 0;
    }
    for (i = 0u; i < 4u; ++i) {
        if (strcmp(key, tables[i]) == 0) {
            return parse_table(val, table_out[i], &table_len[i]);
        }
    }
    for (i = 0u; i < sizeof reals / sizeof reals[0]; ++i) {
        if (strcmp(key, reals[i].key) == 0) {
            return parse_real(val, reals[i].value);
        }
    }
    return -2;
}

int mrs_config_load(const char *path, mrs_config_t *g, char *err, size_t err_len)
{
    char line[MRS_CFG_LINE_MAX];
    int table_len[4] = {-1, -1, -1, -1}; /* -1: not in the file */
    int number = 0, seen_constant = 0, i;
    FILE *f = fopen(path, "r");
    if (f == NULL) {
        (void)snprintf(err, err_len, "cannot read calibration %s", path);
        return -1;
    }
    mrs_default_config(g);
    while (fgets(line, sizeof line, f) != NULL) {
        char *key = line, *val, *eq;
        int rc;
        ++number;
        trim(line);
        while (*key == ' ') {
            ++key;
        }
        if (*key == '\0' || *key == '#' || strncmp(key, "c.", 2u) == 0) {
            continue;
        }
        eq = strchr(key, '=');
        if (eq == NULL) {
            (void)snprintf(err, err_len, "%s:%d: expected 'key = value'", path, number);
            fclose(f);
            return -1;
        }
        *eq = '\0';
        val = eq + 1;
        trim(key);
        while (*val == ' ') {
            ++val;
        }
        rc = set_key(g, key, val, table_len);
        if (rc != 0) {
            (void)snprintf(err, err_len, rc == -2 ? "%s:%d: unknown key '%s'" : "%s:%d: %s: not a valid value",
                           path, number, key);
            fclose(f);
            return -1;
        }
        seen_constant |= (strcmp(key, "k") == 0 || strcmp(key, "tau") == 0 || strcmp(key, "tau_n") == 0);
    }
    fclose(f);
    if (table_len[0] >= 0) {
        for (i = 1; i < 4; ++i) {
            if (table_len[i] != table_len[0]) {
                (void)snprintf(err, err_len, "%s: every schedule_* table needs one value per breakpoint", path);
                return -1;
            }
        }
        g->n_schedule = table_len[0];
        if (g->n_schedule > 0 && (isfinite(g->k) || isfinite(g->tau) || isfinite(g->tau_n)) && seen_constant) {
            (void)snprintf(err, err_len, "%s: give either a gain schedule or constant k, tau, tau_n, not both", path);
            return -1;
        }
    } else if (seen_constant) {
        g->n_schedule = 0; /* constant gains by hand replace the shipped schedule */
    }
    return 0;
}
