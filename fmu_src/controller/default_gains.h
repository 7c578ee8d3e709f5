/*
 * GENERATED FILE - do not edit.  Regenerate with:   python -m controller.gains_defaults
 * Freshness: python -m controller.gains_defaults --check (tests/test_controller/test_hinf.py runs the check).
 * Synthesis inputs hash: cc99080978745865
 *
 * Default first-order blocks x+ = A x + B e, y = C x + D e (Ts = 2 ms, same on the
 * three axes) of the FullPoseController from the structured H-infinity synthesis
 * (controller/hinf.py, docs/robust_design.md): INDI design model with the actuator
 * A(s) = 1/(tau s + 1), the filter H(s), ZOH and the computational delay per cascade;
 * multi-model (mass/inertia mismatch, actuator tau +-30 %); gamma < 1 meets all weights.
 * translation: gamma = 0.9125
 *   loop at input: crossover 6.88 rad/s, GM 18.2 dB, PM 57.4 deg, disk margin 1.079 (gain 0.30..3.34, phase +-56.7 deg)
 *   loop at inner: crossover 6.64 rad/s, GM 18.6 dB, PM 74.8 deg, disk margin 1.354 (gain 0.19..5.19, phase +-68.2 deg)
 *   loop at outer: crossover 2.16 rad/s, GM 21.7 dB, PM 70.6 deg, disk margin 1.214 (gain 0.24..4.09, phase +-62.5 deg)
 * rotation: gamma = 0.9141
 *   loop at input: crossover 23.4 rad/s, GM 7.1 dB, PM 37.6 deg, disk margin 0.581 (gain 0.55..1.82, phase +-32.4 deg)
 *   loop at inner: crossover 21.7 rad/s, GM 8.4 dB, PM 61.1 deg, disk margin 0.755 (gain 0.45..2.21, phase +-41.4 deg)
 *   loop at outer: crossover 8.68 rad/s, GM 10.8 dB, PM 65.5 deg, disk margin 1.009 (gain 0.33..3.03, phase +-53.5 deg)
 */
#ifndef FP_DEFAULT_GAINS_H
#define FP_DEFAULT_GAINS_H

/* The design constants the gains are made for (controller/hinf.py): the
 * controller's defaults of Ts, filt_wn and filt_zeta. */
#define FP_DESIGN_FILT_WN 80.0
#define FP_DESIGN_FILT_ZETA 0.55
#define FP_DESIGN_TS 0.002

static const double fp_default_K_pos_A[3] = {0.99285142777548363, 0.99285142777548363, 0.99285142777548363};
static const double fp_default_K_pos_B[3] = {1, 1, 1};
static const double fp_default_K_pos_C[3] = {0.00095060715775217635, 0.00095060715775217635, 0.00095060715775217635};
static const double fp_default_K_pos_D[3] = {2.0594148444021458, 2.0594148444021458, 2.0594148444021458};
static const double fp_default_K_vel_A[3] = {0.99771146576675762, 0.99771146576675762, 0.99771146576675762};
static const double fp_default_K_vel_B[3] = {1, 1, 1};
static const double fp_default_K_vel_C[3] = {0.0035186092665752755, 0.0035186092665752755, 0.0035186092665752755};
static const double fp_default_K_vel_D[3] = {6.6261092183605115, 6.6261092183605115, 6.6261092183605115};
static const double fp_default_K_att_A[3] = {0.7574371703857794, 0.7574371703857794, 0.7574371703857794};
static const double fp_default_K_att_B[3] = {1, 1, 1};
static const double fp_default_K_att_C[3] = {-0.0019916155331606263, -0.0019916155331606263, -0.0019916155331606263};
static const double fp_default_K_att_D[3] = {8.858096212707542, 8.858096212707542, 8.858096212707542};
static const double fp_default_K_rate_A[3] = {0.93301586404766368, 0.93301586404766368, 0.93301586404766368};
static const double fp_default_K_rate_B[3] = {1, 1, 1};
static const double fp_default_K_rate_C[3] = {-0.62254662041902531, -0.62254662041902531, -0.62254662041902531};
static const double fp_default_K_rate_D[3] = {28.973065956565463, 28.973065956565463, 28.973065956565463};

#endif /* FP_DEFAULT_GAINS_H */
