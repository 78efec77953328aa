/* The calibration file (key = value lines), read into an mrs_config_t: see mrs_calib.h. */
#include "mrs_calib.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define CALIB_LINE_MAX 4096

typedef struct {
    const char *key;
    size_t offset; /* of a double field of mrs_config_t */
} real_key_t;

#define REAL_KEY(name) {#name, offsetof(mrs_config_t, name)}

static const real_key_t REAL_KEYS[] = {
    REAL_KEY(k), REAL_KEY(tau), REAL_KEY(tau_n), REAL_KEY(ts), REAL_KEY(aux_limit), REAL_KEY(rate_limit),
    REAL_KEY(fade_rate), REAL_KEY(speed_active_min), REAL_KEY(speed_max), REAL_KEY(driver_angle_max),
    REAL_KEY(yaw_rate_max), REAL_KEY(nominal_l_f), REAL_KEY(nominal_l_r), REAL_KEY(nominal_mass),
    REAL_KEY(nominal_c_f), REAL_KEY(nominal_c_r),
};

static char *trim(char *s)
{
    size_t n;
    while (*s == ' ' || *s == '\t') {
        ++s;
    }
    n = strlen(s);
    while (n > 0u && (s[n - 1u] == '\n' || s[n - 1u] == '\r' || s[n - 1u] == ' ' || s[n - 1u] == '\t')) {
        s[--n] = '\0';
    }
    return s;
}

/* A whole-string number ("inf" and "nan" as Python writes them included). */
static int parse_real(const char *text, double *out)
{
    char *end;
    errno = 0;
    *out = strtod(text, &end);
    return (end != text && *end == '\0' && errno != ERANGE) ? 0 : -1;
}

/* One "key = value" line into cfg; 0, or -1 with the reason in err. */
static int apply(mrs_config_t *cfg, const char *key, const char *val, mrs_calib_coeff_fn coeff, void *ctx,
                 char *err, size_t err_len)
{
    double x;
    size_t i;
    if (strcmp(key, "q_form") == 0 || strcmp(key, "method") == 0) {
        const int is_q = key[0] == 'q';
        const char *a = is_q ? "limited" : "tustin", *b = is_q ? "standard" : "zoh";
        if (strcmp(val, a) != 0 && strcmp(val, b) != 0) {
            snprintf(err, err_len, "%s must be %s or %s, got '%s'", key, a, b, val);
            return -1;
        }
        if (is_q) {
            cfg->q_form = strcmp(val, b) == 0 ? MRS_Q_STANDARD : MRS_Q_LIMITED;
        } else {
            cfg->method = strcmp(val, b) == 0 ? MRS_ZOH : MRS_TUSTIN;
        }
        return 0;
    }
    if (parse_real(val, &x) != 0) {
        snprintf(err, err_len, "%s: '%s' is not a number", key, val);
        return -1;
    }
    if (strncmp(key, "c.", 2u) == 0) {
        if (coeff != NULL) {
            coeff(ctx, key + 2, x);
        }
        return 0;
    }
    if (strcmp(key, "model_delay_steps") == 0) {
        if (!(x >= 0.0 && x <= 1000.0) || x != floor(x)) {
            snprintf(err, err_len, "model_delay_steps must be a whole number, got '%s'", val);
            return -1;
        }
        cfg->model_delay_steps = (int)x;
        return 0;
    }
    for (i = 0u; i < sizeof REAL_KEYS / sizeof REAL_KEYS[0]; ++i) {
        if (strcmp(key, REAL_KEYS[i].key) == 0) {
            *(double *)(void *)((char *)cfg + REAL_KEYS[i].offset) = x;
            return 0;
        }
    }
    snprintf(err, err_len, "unknown key '%s'", key);
    return -1;
}

int mrs_calib_read(const char *path, mrs_config_t *cfg, mrs_calib_coeff_fn coeff, void *ctx, char *err,
                   size_t err_len)
{
    char line[CALIB_LINE_MAX];
    char why[256];
    long n = 0;
    FILE *f = fopen(path, "r");
    if (f == NULL) {
        snprintf(err, err_len, "cannot read the calibration file %s: %s", path, strerror(errno));
        return -1;
    }
    mrs_default_config(cfg);
    while (fgets(line, sizeof line, f) != NULL) {
        char *text = trim(line), *eq;
        ++n;
        if (text[0] == '#' || text[0] == '\0') {
            continue;
        }
        eq = strchr(text, '=');
        if (eq == NULL) {
            snprintf(err, err_len, "calibration file %s, line %ld: expected key = value", path, n);
            fclose(f);
            return -1;
        }
        *eq = '\0';
        if (apply(cfg, trim(text), trim(eq + 1), coeff, ctx, why, sizeof why) != 0) {
            snprintf(err, err_len, "calibration file %s, line %ld: %s", path, n, why);
            fclose(f);
            return -1;
        }
    }
    fclose(f);
    return 0;
}
