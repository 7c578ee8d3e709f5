/*
 * libfp_multirotor: the C API of the rotor geometry (fp_multirotor_api.h), wrapping the
 * very functions the FMUs run, so Python analysis and tests use the one implementation of
 * the model (no numpy copy).
 */
#include "fp_multirotor_api.h"

#include <string.h>

#include "airframe_vars.h"
#include "multirotor.h"

typedef struct {
    const char *name;
    int32_t rows, cols, integer;
} AirframeRow;

#define AF_ROW(name, vr, type, kind, rows, cols, dtype, range, desc) \
    {#name, rows, cols, FP_##type == FP_INTEGER},
static const AirframeRow airframe_rows[] = {FP_AIRFRAME_VARIABLES(AF_ROW, 0)};
#define N_AIRFRAME_ROWS ((int)(sizeof airframe_rows / sizeof airframe_rows[0]))

FP_API int fp_airframe_variable_count(void) { return N_AIRFRAME_ROWS; }

FP_API int fp_airframe_variable(int i, char *name, int name_size, int32_t *rows, int32_t *cols,
                                int32_t *integer) {
    size_t len;
    if (i < 0 || i >= N_AIRFRAME_ROWS || name == NULL || name_size <= 0) return FP_ERROR;
    len = strlen(airframe_rows[i].name);
    if (len + 1 > (size_t)name_size) return FP_ERROR;
    memcpy(name, airframe_rows[i].name, len + 1);
    *rows = airframe_rows[i].rows, *cols = airframe_rows[i].cols;
    *integer = airframe_rows[i].integer;
    return FP_OK;
}

FP_API int fp_api_version(void) { return 1; }

FP_API int fp_max_rotors(void) { return FP_MAX_ROTORS; }

/* Size in bytes of the opaque rotor-set buffer the functions below take. */
FP_API int fp_rotor_set_size(void) { return (int)sizeof(FpRotorSet); }

FP_API int fp_rotor_set_init(void *buffer, int n, double k_t, double k_d, const double *pos,
                             const int32_t *dir, const double *gamma, const double *alpha_min,
                             const double *alpha_max, const double *beta_min,
                             const double *beta_max, double omega_min, double omega_max) {
    FpRotorSet *rs = (FpRotorSet *)buffer;
    int i;
    if (rs == NULL || n < 1 || n > FP_MAX_ROTORS || !(k_t > 0.0)) return FP_ERROR;
    memset(rs, 0, sizeof *rs);
    rs->n = n;
    rs->k_t = k_t;
    rs->k_d = k_d;
    for (i = 0; i < n; i++) {
        memcpy(rs->pos[i], pos + 3 * i, 3 * sizeof(double));
        rs->dir[i] = dir[i];
        rs->gamma[i] = gamma[i];
        rs->alpha_min[i] = alpha_min[i];
        rs->alpha_max[i] = alpha_max[i];
        rs->beta_min[i] = beta_min[i];
        rs->beta_max[i] = beta_max[i];
    }
    rs->omega_min = omega_min;
    rs->omega_max = omega_max;
    return FP_OK;
}

FP_API int fp_rotor_rotation_api(double alpha, double beta, double gamma, double *r9) {
    fp_rotor_rotation(alpha, beta, gamma, (double(*)[3])r9);
    return FP_OK;
}

FP_API int fp_thrust_direction_api(double alpha, double beta, double gamma, double *t3) {
    fp_thrust_direction(alpha, beta, gamma, t3);
    return FP_OK;
}

FP_API int fp_tilt_from_direction_api(const double *f3, double gamma, double *alpha, double *beta) {
    fp_tilt_from_direction(f3, gamma, alpha, beta);
    return FP_OK;
}

FP_API int fp_effectiveness_b_api(const void *rotor_set, double *b) {
    return fp_effectiveness_b((const FpRotorSet *)rotor_set, b);
}

FP_API int fp_effectiveness_bprime_api(const void *rotor_set, const double *alpha,
                                       const double *beta, double *bp) {
    return fp_effectiveness_bprime((const FpRotorSet *)rotor_set, alpha, beta, bp);
}

FP_API int fp_rotor_wrench_api(const void *rotor_set, const double *alpha, const double *beta,
                               const double *omega, const double *efficiency, double *f_b,
                               double *tau_b) {
    fp_rotor_wrench((const FpRotorSet *)rotor_set, alpha, beta, omega, efficiency, f_b, tau_b);
    return FP_OK;
}

FP_API int fp_preferred_config_api(const void *rotor_set, const double *wrench, double *alpha,
                                   double *beta, double *omega, char *why, int why_size) {
    return fp_preferred_config((const FpRotorSet *)rotor_set, wrench, alpha, beta, omega, why,
                               why_size);
}

FP_API int fp_effectiveness_b2prime_api(const void *rotor_set, const double *alpha,
                                        const double *beta, const double *omega, double *b2p) {
    return fp_effectiveness_b2prime((const FpRotorSet *)rotor_set, alpha, beta, omega, b2p);
}
