/*
 * libfp_multirotor: the C API of the rotor geometry (fp_multirotor_api.h), wrapping the
 * very functions the FMUs run, so Python analysis and tests use the one implementation of
 * the model (no numpy copy).
 */
#include "fp_multirotor_api.h"

#include <stddef.h>
#include <string.h>

#include "airframe_vars.h"
#include "multirotor.h"

typedef struct {
    const char *name;
    int32_t rows, cols, integer, offset;
} AirframeRow;

#define AF_ROW(name, vr, type, kind, rows, cols, dtype, range, desc) \
    {#name, rows, cols, FP_##type == FP_INTEGER, (int32_t)offsetof(FpAirframe, name)},
static const AirframeRow airframe_rows[] = {FP_AIRFRAME_VARIABLES(AF_ROW, 0)};
#define N_AIRFRAME_ROWS ((int)(sizeof airframe_rows / sizeof airframe_rows[0]))

FP_API int fp_airframe_variable_count(void) { return N_AIRFRAME_ROWS; }

FP_API int fp_airframe_variable(int i, char *name, int name_size, int32_t *rows, int32_t *cols,
                                int32_t *integer, int32_t *offset) {
    size_t len;
    if (i < 0 || i >= N_AIRFRAME_ROWS || name == NULL || name_size <= 0) return FP_ERROR;
    len = strlen(airframe_rows[i].name);
    if (len + 1 > (size_t)name_size) return FP_ERROR;
    memcpy(name, airframe_rows[i].name, len + 1);
    *rows = airframe_rows[i].rows, *cols = airframe_rows[i].cols;
    *integer = airframe_rows[i].integer;
    *offset = airframe_rows[i].offset;
    return FP_OK;
}

FP_API int fp_airframe_size(void) { return (int)sizeof(FpAirframe); }

FP_API int fp_rotor_set_from_airframe(const void *airframe, void *rotor_set) {
    const FpAirframe *af = (const FpAirframe *)airframe;
    if (af == NULL || rotor_set == NULL || af->n_rotors < 1 || af->n_rotors > FP_MAX_ROTORS ||
        !(af->k_t > 0.0))
        return FP_ERROR;
    fp_rotor_set_of(af, (FpRotorSet *)rotor_set);
    return FP_OK;
}

FP_API int fp_api_version(void) { return 1; }

FP_API int fp_max_rotors(void) { return FP_MAX_ROTORS; }

/* Size in bytes of the opaque rotor-set buffer the functions below take. */
FP_API int fp_rotor_set_size(void) { return (int)sizeof(FpRotorSet); }

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
