/*
 * GENERATED FILE - do not edit.  Regenerate with:   python -m controller.gains_defaults
 * Freshness: python -m controller.gains_defaults --check (tests/test_hinf.py runs the check).
 * Synthesis inputs hash: cbdb3bfbbdbd10ab
 *
 * Default first-order blocks x+ = A x + B e, y = C x + D e (Ts = 2 ms, same on the
 * three axes) of the FullPoseController from the structured H-infinity synthesis
 * (controller/hinf.py, docs/robust_design.md): INDI design model with the actuator
 * A(s) = 1/(tau s + 1), the filter H(s), ZOH and the computational delay per cascade;
 * multi-model (mass/inertia mismatch, actuator tau +-30 %); gamma < 1 meets all weights.
 * translation: gamma = 0.9546
 *   loop at input: crossover 11.5 rad/s, GM 9.7 dB, PM 52.6 deg, disk margin 0.825 (gain 0.42..2.41, phase +-44.9 deg)
 *   loop at inner: crossover 11.5 rad/s, GM 10.1 dB, PM 61.7 deg, disk margin 0.880 (gain 0.39..2.57, phase +-47.5 deg)
 *   loop at outer: crossover 2.07 rad/s, GM 20.0 dB, PM 76.3 deg, disk margin 1.402 (gain 0.18..5.69, phase +-70.1 deg)
 * rotation: gamma = 0.9561
 *   loop at input: crossover 15 rad/s, GM 7.3 dB, PM 50.7 deg, disk margin 0.679 (gain 0.49..2.03, phase +-37.5 deg)
 *   loop at inner: crossover 13.8 rad/s, GM 8.2 dB, PM 73.4 deg, disk margin 0.774 (gain 0.44..2.26, phase +-42.3 deg)
 *   loop at outer: crossover 5.2 rad/s, GM 13.9 dB, PM 65.8 deg, disk margin 1.129 (gain 0.28..3.59, phase +-58.9 deg)
 */
#ifndef FP_DEFAULT_GAINS_H
#define FP_DEFAULT_GAINS_H

static const double fp_default_K_pos_A[3] = {0.98952459450061969, 0.98952459450061969, 0.98952459450061969};
static const double fp_default_K_pos_B[3] = {1, 1, 1};
static const double fp_default_K_pos_C[3] = {0.0037303117597425094, 0.0037303117597425094, 0.0037303117597425094};
static const double fp_default_K_pos_D[3] = {1.7566417379179082, 1.7566417379179082, 1.7566417379179082};
static const double fp_default_K_vel_A[3] = {0.99826924971653708, 0.99826924971653708, 0.99826924971653708};
static const double fp_default_K_vel_B[3] = {1, 1, 1};
static const double fp_default_K_vel_C[3] = {2.1925249262510359e-15, 2.1925249262510359e-15, 2.1925249262510359e-15};
static const double fp_default_K_vel_D[3] = {11.533705912449486, 11.533705912449486, 11.533705912449486};
static const double fp_default_K_att_A[3] = {0.84502344231804516, 0.84502344231804516, 0.84502344231804516};
static const double fp_default_K_att_B[3] = {1, 1, 1};
static const double fp_default_K_att_C[3] = {0.0066301659091429904, 0.0066301659091429904, 0.0066301659091429904};
static const double fp_default_K_att_D[3] = {5.4881345969677406, 5.4881345969677406, 5.4881345969677406};
static const double fp_default_K_rate_A[3] = {0.94392657616415665, 0.94392657616415665, 0.94392657616415665};
static const double fp_default_K_rate_B[3] = {1, 1, 1};
static const double fp_default_K_rate_C[3] = {-0.53317606218900737, -0.53317606218900737, -0.53317606218900737};
static const double fp_default_K_rate_D[3] = {21.008750898399523, 21.008750898399523, 21.008750898399523};

#endif /* FP_DEFAULT_GAINS_H */
