/*
 * GENERATED FILE - do not edit.  Regenerate with:   python -m controller.gains_defaults
 * Freshness: python -m controller.gains_defaults --check (tests/test_hinf.py runs the check).
 * Synthesis inputs hash: 5388edb534941a7d
 *
 * Default first-order blocks x+ = A x + B e, y = C x + D e (Ts = 2 ms, same on the
 * three axes) of the FullPoseController from the structured H-infinity synthesis
 * (controller/hinf.py, docs/robust_design.md): INDI design model with the actuator
 * A(s) = 1/(tau s + 1), the filter H(s), ZOH and the computational delay per cascade;
 * multi-model (mass/inertia mismatch, actuator tau +-30 %); gamma < 1 meets all weights.
 * translation: gamma = 0.9411
 *   loop at input: crossover 11.4 rad/s, GM 9.9 dB, PM 59.4 deg, disk margin 0.861 (gain 0.40..2.51, phase +-46.6 deg)
 *   loop at inner: crossover 11.7 rad/s, GM 10.0 dB, PM 63.6 deg, disk margin 0.880 (gain 0.39..2.57, phase +-47.5 deg)
 *   loop at outer: crossover 1.66 rad/s, GM 24.2 dB, PM 70.9 deg, disk margin 1.279 (gain 0.22..4.55, phase +-65.2 deg)
 * rotation: gamma = 1.4107
 *   loop at input: crossover 18.9 rad/s, GM 5.5 dB, PM 40.0 deg, disk margin 0.516 (gain 0.59..1.69, phase +-28.9 deg)
 *   loop at inner: crossover 16.2 rad/s, GM 7.0 dB, PM 71.9 deg, disk margin 0.678 (gain 0.49..2.03, phase +-37.4 deg)
 *   loop at outer: crossover 8.32 rad/s, GM 9.4 dB, PM 57.7 deg, disk margin 0.940 (gain 0.36..2.77, phase +-50.3 deg)
 */
#ifndef FP_DEFAULT_GAINS_H
#define FP_DEFAULT_GAINS_H

static const double fp_default_K_pos_A[3] = {0.99113618830865668, 0.99113618830865668, 0.99113618830865668};
static const double fp_default_K_pos_B[3] = {1, 1, 1};
static const double fp_default_K_pos_C[3] = {0.008686271942581536, 0.008686271942581536, 0.008686271942581536};
static const double fp_default_K_pos_D[3] = {0.8343477079793753, 0.8343477079793753, 0.8343477079793753};
static const double fp_default_K_vel_A[3] = {0.99835516176975891, 0.99835516176975891, 0.99835516176975891};
static const double fp_default_K_vel_B[3] = {1, 1, 1};
static const double fp_default_K_vel_C[3] = {-0.011579677161462408, -0.011579677161462408, -0.011579677161462408};
static const double fp_default_K_vel_D[3] = {11.760495653469523, 11.760495653469523, 11.760495653469523};
static const double fp_default_K_att_A[3] = {4.1905815703085232e-70, 4.1905815703085232e-70, 4.1905815703085232e-70};
static const double fp_default_K_att_B[3] = {1, 1, 1};
static const double fp_default_K_att_C[3] = {0.04615830432022492, 0.04615830432022492, 0.04615830432022492};
static const double fp_default_K_att_D[3] = {9.2034091973846017, 9.2034091973846017, 9.2034091973846017};
static const double fp_default_K_rate_A[3] = {0.92864692613536115, 0.92864692613536115, 0.92864692613536115};
static const double fp_default_K_rate_B[3] = {1, 1, 1};
static const double fp_default_K_rate_C[3] = {-1.0569224084256605, -1.0569224084256605, -1.0569224084256605};
static const double fp_default_K_rate_D[3] = {27.612658254001659, 27.612658254001659, 27.612658254001659};

#endif /* FP_DEFAULT_GAINS_H */
