/*
 * GENERATED FILE - do not edit.  Regenerate with:   python -m controller.gains_defaults
 * Freshness: python -m controller.gains_defaults --check (tests/test_hinf.py runs the check).
 * Synthesis inputs hash: 75147ffd62ab343a
 *
 * Default first-order blocks x+ = A x + B e, y = C x + D e (Ts = 2 ms, same on the
 * three axes) of the FullPoseController from the structured H-infinity synthesis
 * (controller/hinf.py, docs/robust_design.md): INDI design model with the actuator
 * A(s) = 1/(tau s + 1), the filter H(s), ZOH and the computational delay per cascade;
 * multi-model (mass/inertia mismatch, actuator tau +-30 %); gamma < 1 meets all weights.
 * translation: gamma = 0.9343
 *   loop at input: crossover 6.57 rad/s, GM 14.9 dB, PM 55.3 deg, disk margin 1.046 (gain 0.31..3.19, phase +-55.2 deg)
 *   loop at inner: crossover 6.32 rad/s, GM 15.3 dB, PM 73.7 deg, disk margin 1.247 (gain 0.23..4.31, phase +-63.9 deg)
 *   loop at outer: crossover 2.12 rad/s, GM 19.7 dB, PM 70.1 deg, disk margin 1.194 (gain 0.25..3.96, phase +-61.7 deg)
 * rotation: gamma = 0.9844
 *   loop at input: crossover 16.6 rad/s, GM 6.6 dB, PM 33.3 deg, disk margin 0.548 (gain 0.57..1.76, phase +-30.7 deg)
 *   loop at inner: crossover 15 rad/s, GM 8.2 dB, PM 61.6 deg, disk margin 0.756 (gain 0.45..2.22, phase +-41.4 deg)
 *   loop at outer: crossover 7.52 rad/s, GM 9.3 dB, PM 60.0 deg, disk margin 0.864 (gain 0.40..2.52, phase +-46.7 deg)
 */
#ifndef FP_DEFAULT_GAINS_H
#define FP_DEFAULT_GAINS_H

static const double fp_default_K_pos_A[3] = {0.98957584034304558, 0.98957584034304558, 0.98957584034304558};
static const double fp_default_K_pos_B[3] = {1, 1, 1};
static const double fp_default_K_pos_C[3] = {0.0012499401734597897, 0.0012499401734597897, 0.0012499401734597897};
static const double fp_default_K_pos_D[3] = {2.0440577136106128, 2.0440577136106128, 2.0440577136106128};
static const double fp_default_K_vel_A[3] = {0.9969102200839608, 0.9969102200839608, 0.9969102200839608};
static const double fp_default_K_vel_B[3] = {1, 1, 1};
static const double fp_default_K_vel_C[3] = {0.0012282769335337795, 0.0012282769335337795, 0.0012282769335337795};
static const double fp_default_K_vel_D[3] = {6.2975855466391515, 6.2975855466391515, 6.2975855466391515};
static const double fp_default_K_att_A[3] = {0.99667297952763045, 0.99667297952763045, 0.99667297952763045};
static const double fp_default_K_att_B[3] = {1, 1, 1};
static const double fp_default_K_att_C[3] = {0.00011234417362183634, 0.00011234417362183634, 0.00011234417362183634};
static const double fp_default_K_att_D[3] = {7.6275109254655487, 7.6275109254655487, 7.6275109254655487};
static const double fp_default_K_rate_A[3] = {0.92732300872086026, 0.92732300872086026, 0.92732300872086026};
static const double fp_default_K_rate_B[3] = {1, 1, 1};
static const double fp_default_K_rate_C[3] = {-0.37502390452531248, -0.37502390452531248, -0.37502390452531248};
static const double fp_default_K_rate_D[3] = {19.375871685714262, 19.375871685714262, 19.375871685714262};

#endif /* FP_DEFAULT_GAINS_H */
