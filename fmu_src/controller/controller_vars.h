/*
 * FullPoseController: THE variable table (see plant/plant_vars.h for the
 * format).  Measured inputs carry the same names as the plant's outputs and
 * the actuator commands the same names as the plant's inputs, so a master
 * connects the two FMUs by matching names.
 *
 * X(name, value reference, type, kind, rows, cols, declared type, range, description)
 *
 * The ranges of the inputs are their plausible ranges (docs/robustness.md): a sample whose
 * inputs leave them is held (controller.c inputs_usable).  The measured actuator angles
 * alpha, beta are checked against the airframe's servo limits +- CTRL_SERVO_MARGIN, which
 * no static range can state: their range is the widest that check can allow (servo limits
 * within +-pi/2); the measured rotor speeds omega, checked against [-omega_max,
 * 2 omega_max] with omega_max unbounded, have none.
 */
#ifndef CONTROLLER_VARS_H
#define CONTROLLER_VARS_H

#include "airframe_vars.h"

/* The plausible ranges of the inputs (docs/robustness.md), shared by the references and the
 * measurements of the same quantity. */
#define CTRL_MAX_DISTANCE 1e7 /* m */
#define CTRL_MAX_SPEED 1e3    /* m/s */
#define CTRL_MAX_ACC 1e4      /* m/s^2 */
#define CTRL_MAX_ANGLE 1e3    /* rad (Euler angles) */
#define CTRL_MAX_RATE 1e3     /* rad/s */
#define CTRL_SERVO_MARGIN 0.78539816339744830962 /* pi/4: rad beyond the servo limits */
#define CTRL_MAX_SERVO (FP_SERVO_LIMIT + CTRL_SERVO_MARGIN) /* 3 pi/4 */

#define CONTROLLER_VARIABLES(X, XAF)                                                                    \
    /* parameters: sampling */                                        \
    X(Ts, 1, REAL, PARAM_FIXED, 1, 1, TIME, FP_POSITIVE, "Sample time; samples run at t0 + k Ts for any communication step, outputs held between them") \
    /* parameters: the airframe model (common/airframe_vars.h), shared with the plant */          \
    FP_AIRFRAME_VARIABLES(XAF, 1)                                                                  \
    /* parameters: measurement filter H(s) = wn^2 / (s^2 + 2 zeta wn s + wn^2) */                  \
    X(filt_wn, 120, REAL, PARAM_FIXED, 1, 1, ANGULAR_FREQUENCY, FP_POSITIVE, "Natural frequency of H(s)") \
    X(filt_zeta, 121, REAL, PARAM_FIXED, 1, 1, RATIO, FP_POSITIVE, "Damping ratio of H(s)")        \
    /* parameters: first-order blocks x+ = A x + B e, y = C x + D e (discrete, per axis) */        \
    X(K_pos_A, 130, REAL, PARAM_TUNABLE, 3, 1, DIMENSIONLESS, FP_IN_OPEN(-1, 1), "Position block K_xi: A") \
    X(K_pos_B, 133, REAL, PARAM_TUNABLE, 3, 1, DIMENSIONLESS, FP_ANY, "Position block K_xi: B")    \
    X(K_pos_C, 136, REAL, PARAM_TUNABLE, 3, 1, BLOCK_GAIN, FP_ANY, "Position block K_xi: C")       \
    X(K_pos_D, 139, REAL, PARAM_TUNABLE, 3, 1, BLOCK_GAIN, FP_ANY, "Position block K_xi: D (1/s)") \
    X(K_vel_A, 150, REAL, PARAM_TUNABLE, 3, 1, DIMENSIONLESS, FP_IN_OPEN(-1, 1), "Velocity block K_xidot: A") \
    X(K_vel_B, 153, REAL, PARAM_TUNABLE, 3, 1, DIMENSIONLESS, FP_ANY, "Velocity block K_xidot: B") \
    X(K_vel_C, 156, REAL, PARAM_TUNABLE, 3, 1, BLOCK_GAIN, FP_ANY, "Velocity block K_xidot: C")    \
    X(K_vel_D, 159, REAL, PARAM_TUNABLE, 3, 1, BLOCK_GAIN, FP_ANY, "Velocity block K_xidot: D (1/s)") \
    X(K_att_A, 170, REAL, PARAM_TUNABLE, 3, 1, DIMENSIONLESS, FP_IN_OPEN(-1, 1), "Attitude block: A") \
    X(K_att_B, 173, REAL, PARAM_TUNABLE, 3, 1, DIMENSIONLESS, FP_ANY, "Attitude block: B")         \
    X(K_att_C, 176, REAL, PARAM_TUNABLE, 3, 1, BLOCK_GAIN, FP_ANY, "Attitude block: C")            \
    X(K_att_D, 179, REAL, PARAM_TUNABLE, 3, 1, BLOCK_GAIN, FP_ANY, "Attitude block: D (1/s)")      \
    X(K_rate_A, 190, REAL, PARAM_TUNABLE, 3, 1, DIMENSIONLESS, FP_IN_OPEN(-1, 1), "Rate block: A") \
    X(K_rate_B, 193, REAL, PARAM_TUNABLE, 3, 1, DIMENSIONLESS, FP_ANY, "Rate block: B")            \
    X(K_rate_C, 196, REAL, PARAM_TUNABLE, 3, 1, BLOCK_GAIN, FP_ANY, "Rate block: C")               \
    X(K_rate_D, 199, REAL, PARAM_TUNABLE, 3, 1, BLOCK_GAIN, FP_ANY, "Rate block: D (1/s)")         \
    /* parameters: guidance allocation (eq. 17-23) */                                              \
    X(gamma_opt, 210, REAL, PARAM_TUNABLE, 1, 1, WEIGHT, FP_POSITIVE, "Weight of the acceleration-tracking term") \
    X(W_u, 211, REAL, PARAM_TUNABLE, 5, 1, WEIGHT, FP_POSITIVE, "Diagonal of W_u for [dfx, dfy, dfz, dphi, dtheta]") \
    X(W_v, 216, REAL, PARAM_TUNABLE, 3, 1, WEIGHT, FP_POSITIVE, "Diagonal of W_v (world x, y, z)") \
    X(euler_min, 220, REAL, PARAM_TUNABLE, 2, 1, ANGLE, FP_IN_OPEN(-FP_SERVO_LIMIT, FP_SERVO_LIMIT), "Lower bounds of [phi_c, theta_c]") \
    X(euler_max, 222, REAL, PARAM_TUNABLE, 2, 1, ANGLE, FP_IN_OPEN(-FP_SERVO_LIMIT, FP_SERVO_LIMIT), "Upper bounds of [phi_c, theta_c]") \
    X(force_constraint, 224, INTEGER, PARAM_FIXED, 1, 1, NONE, FP_IN(0, 1), "0: joint 3-D polytope S(0); 1: paper's slice P_xy at f_bz_ref plus f_bz bounds") \
    X(poly_n, 230, INTEGER, PARAM_FIXED, 1, 1, NONE, FP_IN(0, FP_POLYTOPE_MAX_FACETS), "Facets of the feasible-force polytope S(0) given in poly_A, poly_b (4..64); 0: S(0) derived from the airframe parameters at initialization") \
    X(poly_A, 300, REAL, PARAM_FIXED, 64, 3, DIMENSIONLESS, FP_ANY, "Feasible-force polytope S(0) when poly_n > 0: A f_b <= b, unit normals (checked against the airframe)") \
    X(poly_b, 500, REAL, PARAM_FIXED, 64, 1, FORCE, FP_ANY, "Feasible-force polytope S(0) when poly_n > 0: offsets b") \
    X(fail_poly_n, 570, INTEGER, PARAM_FIXED, 8, 1, NONE, FP_IN(0, FP_FAIL_POLYTOPE_FACETS), "Facets of S(0) after losing rotor i given in fail_poly_A, fail_poly_b (4..32); 0: derived from the airframe parameters at initialization") \
    X(fail_poly_A, 3000, REAL, PARAM_FIXED, 256, 3, DIMENSIONLESS, FP_ANY, "S(0) after losing rotor i: rows 32 (i-1) + 1 .. 32 (i-1) + fail_poly_n[i], unit normals") \
    X(fail_poly_b, 4000, REAL, PARAM_FIXED, 256, 1, FORCE, FP_ANY, "S(0) after losing rotor i: offsets (rows as fail_poly_A)") \
    X(poly_margin, 564, REAL, PARAM_FIXED, 1, 1, RATIO, FP_IN_LOPEN(0, 1), "Scale (0, 1] of S(0) about the hover force used by the guidance: reserve for attitude torques") \
    /* parameters: inner allocation (eq. 12-13) */                                                 \
    X(W_nu, 600, REAL, PARAM_TUNABLE, 6, 1, WEIGHT, FP_POSITIVE, "Row weights of [df_b; dtau_b] (torque priority)") \
    X(yaw_rate_max, 610, REAL, PARAM_TUNABLE, 1, 1, ANGULAR_VELOCITY, FP_NONNEGATIVE, "Limit of the commanded heading rate; 0: 1.25 x the heading-rate limit of the shaping in use (ref_att_rate_limit[3])") \
    X(w_pref, 606, REAL, PARAM_TUNABLE, 1, 1, WEIGHT, FP_POSITIVE, "Weight of the preferred actuator configuration") \
    X(pref_omega_scale, 607, REAL, PARAM_TUNABLE, 1, 1, ROTOR_SPEED, FP_POSITIVE, "Scale of rotor speeds (in rad/s) in the preference term") \
    X(qp_max_iter, 608, INTEGER, PARAM_TUNABLE, 1, 1, NONE, FP_IN(1, 1000), "Iteration cap of both allocation QPs") \
    X(timing, 609, BOOLEAN, PARAM_FIXED, 1, 1, NONE, FP_ANY, "Measure computation times (t_step, t_guid, t_alloc); off keeps runs bit-reproducible") \
    /* parameters: reference shaping (reference.c) */                                             \
    X(ref_shaping, 640, BOOLEAN, PARAM_FIXED, 1, 1, NONE, FP_ANY, "Shape the reference: jumps of pos_ref, its derivatives and euler_ref are flown within the limits below (off: the reference as given)") \
    X(ref_bandwidth, 641, REAL, PARAM_FIXED, 1, 1, ANGULAR_FREQUENCY, FP_POSITIVE, "Poles of the shaping in its linear region (triple for translation, double for the angles); derived jerk limits reach the acceleration limit within 1 / ref_bandwidth") \
    X(ref_tilt_max, 642, REAL, PARAM_FIXED, 1, 1, ANGLE, FP_IN_OPEN(0, 1.5), "Tilt the shaped horizontal acceleration may need (vehicles whose force follows their attitude: derived ref_acc_max[1] = 0.9 g tan(ref_tilt_max))") \
    X(ref_vel_max, 643, REAL, PARAM_FIXED, 2, 1, VELOCITY, FP_NONNEGATIVE, "Speed limits of the shaped correction [horizontal, vertical]; 0: derived, the acceleration limit times 1 s (ref_vel_limit)") \
    X(ref_acc_max, 645, REAL, PARAM_FIXED, 2, 1, ACCELERATION, FP_NONNEGATIVE, "Acceleration limits of the shaped correction [horizontal, vertical]; 0: derived from the feasible-force set and ref_tilt_max (ref_acc_limit, docs/controller.md)") \
    X(ref_jerk_max, 647, REAL, PARAM_FIXED, 2, 1, JERK, FP_NONNEGATIVE, "Jerk limits of the shaped correction [horizontal, vertical]; 0: derived, the acceleration limit times ref_bandwidth (ref_jerk_limit)") \
    X(ref_att_rate_max, 649, REAL, PARAM_FIXED, 3, 1, ANGULAR_VELOCITY, FP_NONNEGATIVE, "Euler-rate limits of the shaped attitude correction [roll, pitch, heading]; 0: derived, the acceleration limit times 1 s (ref_att_rate_limit)") \
    X(ref_att_acc_max, 652, REAL, PARAM_FIXED, 3, 1, ANGULAR_ACCELERATION, FP_NONNEGATIVE, "Euler-acceleration limits of the shaped attitude correction [roll, pitch, heading]; 0: derived, half the torque the rotors give about that axis at hover over the inertia (ref_att_acc_limit)") \
    X(fault_detect, 660, BOOLEAN, PARAM_FIXED, 1, 1, NONE, FP_ANY, "Detect a lost or degraded rotor from the INDI residual without being told, and reconfigure (docs/controller.md)") \
    X(fault_loss_min, 661, REAL, PARAM_FIXED, 1, 1, RATIO, FP_IN_OPEN(0, 1), "Smallest change of a rotor's efficiency the detector concludes (an event opens at half of it, as an acceleration of that share of the rotor's weight share)") \
    X(fault_fit_max, 662, REAL, PARAM_FIXED, 1, 1, RATIO, FP_IN_OPEN(0, 1), "Share of an event's residual change (beyond sensor noise) a rotor's own wrench may leave unexplained for a fault to be concluded") \
    X(fault_time, 663, REAL, PARAM_FIXED, 1, 1, TIME, FP_POSITIVE, "Least time an event is fitted before it may conclude a rotor fault") \
    /* inputs: references */                                                                       \
    X(pos_ref, 1000, REAL, INPUT, 3, 1, LENGTH, FP_IN(-CTRL_MAX_DISTANCE, CTRL_MAX_DISTANCE), "Reference position xi_ref, world NED") \
    X(euler_ref, 1003, REAL, INPUT, 3, 1, ANGLE, FP_IN(-CTRL_MAX_ANGLE, CTRL_MAX_ANGLE), "Reference attitude mu_ref") \
    X(vel_ref, 1006, REAL, INPUT, 3, 1, VELOCITY, FP_IN(-CTRL_MAX_SPEED, CTRL_MAX_SPEED), "Velocity feed-forward (derivative of pos_ref)") \
    X(acc_ref, 1009, REAL, INPUT, 3, 1, ACCELERATION, FP_IN(-CTRL_MAX_ACC, CTRL_MAX_ACC), "Acceleration feed-forward (second derivative of pos_ref)") \
    X(euler_rate_ref, 1012, REAL, INPUT, 3, 1, ANGULAR_VELOCITY, FP_IN(-CTRL_MAX_RATE, CTRL_MAX_RATE), "Euler-rate feed-forward (derivative of euler_ref)") \
    /* inputs: measurements (plant outputs) */                                                     \
    X(pos, 1100, REAL, INPUT, 3, 1, LENGTH, FP_IN(-CTRL_MAX_DISTANCE, CTRL_MAX_DISTANCE), "Measured position, world NED") \
    X(vel, 1103, REAL, INPUT, 3, 1, VELOCITY, FP_IN(-CTRL_MAX_SPEED, CTRL_MAX_SPEED), "Measured velocity, world NED") \
    X(acc, 1106, REAL, INPUT, 3, 1, ACCELERATION, FP_IN(-CTRL_MAX_ACC, CTRL_MAX_ACC), "Measured acceleration, world NED") \
    X(euler, 1109, REAL, INPUT, 3, 1, ANGLE, FP_IN(-CTRL_MAX_ANGLE, CTRL_MAX_ANGLE), "Measured attitude [phi, theta, psi]") \
    X(rate, 1112, REAL, INPUT, 3, 1, ANGULAR_VELOCITY, FP_IN(-CTRL_MAX_RATE, CTRL_MAX_RATE), "Measured body rates") \
    X(omega, 1120, REAL, INPUT, 8, 1, ROTOR_SPEED, FP_ANY, "Measured rotor speeds")                \
    X(alpha, 1130, REAL, INPUT, 8, 1, ANGLE, FP_IN(-CTRL_MAX_SERVO, CTRL_MAX_SERVO), "Measured servo angles alpha") \
    X(beta, 1140, REAL, INPUT, 8, 1, ANGLE, FP_IN(-CTRL_MAX_SERVO, CTRL_MAX_SERVO), "Measured servo angles beta") \
    X(rotor_health, 1150, REAL, INPUT, 8, 1, RATIO, FP_IN(0, 1), "Known rotor efficiency 0..1 (below 0.5: lost; the allocations exclude it)") \
    X(pose_age, 1160, REAL, INPUT, 1, 1, TIME, FP_IN(0, 1), "Age of pos, vel and euler: the time since the state they show (0: current); the controller predicts them to now with acc and rate") \
    X(armed, 1170, BOOLEAN, INPUT, 1, 1, NONE, FP_ANY, "Armed: the rotors may spin (false: they stop, and the controller restarts from the measurements when armed again)") \
    /* outputs: actuator commands (plant inputs) */                                                \
    X(omega_cmd, 2000, REAL, OUTPUT, 8, 1, ROTOR_SPEED, FP_ANY, "Rotor speed commands")            \
    X(alpha_cmd, 2010, REAL, OUTPUT, 8, 1, ANGLE, FP_ANY, "Servo commands alpha")                  \
    X(beta_cmd, 2020, REAL, OUTPUT, 8, 1, ANGLE, FP_ANY, "Servo commands beta")                    \
    /* outputs: diagnostics */                                                                     \
    X(mu_c, 2030, REAL, OUTPUT, 3, 1, ANGLE, FP_ANY, "Commanded feasible attitude mu_c")           \
    X(f_b_ref, 2033, REAL, OUTPUT, 3, 1, FORCE, FP_ANY, "Body force required to follow xi_ref at the measured attitude (eq. 21)") \
    X(f_b_c, 2036, REAL, OUTPUT, 3, 1, FORCE, FP_ANY, "Commanded body force f_b_m + df_b_c")       \
    X(feasible, 2039, BOOLEAN, OUTPUT, 1, 1, NONE, FP_ANY, "The reference pose is feasible: R_ref^T f_w_ref lies in S(0) (eq. 7)") \
    X(guid_status, 2040, INTEGER, OUTPUT, 1, 1, NONE, FP_ANY, "Guidance QP status: 0 optimal, 1 iteration cap, 2 infeasible, 3 bad input") \
    X(guid_iter, 2041, INTEGER, OUTPUT, 1, 1, NONE, FP_ANY, "Guidance QP iterations")              \
    X(alloc_status, 2042, INTEGER, OUTPUT, 1, 1, NONE, FP_ANY, "Inner allocation QP status (as guid_status)") \
    X(alloc_iter, 2043, INTEGER, OUTPUT, 1, 1, NONE, FP_ANY, "Inner allocation QP iterations")     \
    X(sat_flags, 2044, INTEGER, OUTPUT, 1, 1, NONE, FP_ANY, "Commands at a limit: bit i-1 motor i, bit 7+i alpha i, bit 15+i beta i") \
    X(guid_flags, 2045, INTEGER, OUTPUT, 1, 1, NONE, FP_ANY, "Active guidance constraints: bit 0 force set, bit 1 phi bound, bit 2 theta bound") \
    X(acc_c, 2050, REAL, OUTPUT, 3, 1, ACCELERATION, FP_ANY, "Commanded acceleration (outer blocks plus feed-forward)") \
    X(rate_c, 2053, REAL, OUTPUT, 3, 1, ANGULAR_VELOCITY, FP_ANY, "Commanded body rates")          \
    X(dnu_c, 2056, REAL, OUTPUT, 6, 1, WRENCH, FP_ANY, "Virtual control increment [df_b (N); dtau_b (N.m)]") \
    X(alloc_residual, 2062, REAL, OUTPUT, 6, 1, WRENCH, FP_ANY, "Allocation residual B'' du - dnu_c [N; N.m]") \
    X(rotors_lost, 2080, INTEGER, OUTPUT, 1, 1, NONE, FP_ANY, "Number of rotors the controller treats as lost") \
    X(hover_possible, 2081, BOOLEAN, OUTPUT, 1, 1, NONE, FP_ANY, "The hover force lies in the feasible-force set in use (false: the vehicle cannot hold hover)") \
    X(active_polytope, 2082, INTEGER, OUTPUT, 1, 1, NONE, FP_ANY, "Feasible-force set in use: 0 nominal, i: after losing rotor i, -1: several rotors lost (nominal set, no guarantee)") \
    X(t_step, 2070, REAL, OUTPUT, 1, 1, TIME, FP_ANY, "Computation time of the last controller sample (0 unless timing)") \
    X(t_guid, 2071, REAL, OUTPUT, 1, 1, TIME, FP_ANY, "Computation time of the last guidance QP solve (0 unless timing)") \
    X(t_alloc, 2072, REAL, OUTPUT, 1, 1, TIME, FP_ANY, "Computation time of the last inner allocation QP solve (0 unless timing)") \
    X(pos_ref_s, 2110, REAL, OUTPUT, 3, 1, LENGTH, FP_ANY, "Shaped position reference (pos_ref where no jump is being shaped)") \
    X(vel_ref_s, 2113, REAL, OUTPUT, 3, 1, VELOCITY, FP_ANY, "Shaped velocity reference") \
    X(acc_ref_s, 2116, REAL, OUTPUT, 3, 1, ACCELERATION, FP_ANY, "Shaped acceleration reference") \
    X(euler_ref_s, 2119, REAL, OUTPUT, 3, 1, ANGLE, FP_ANY, "Shaped attitude reference (heading unwrapped)") \
    X(mu_ff, 2122, REAL, OUTPUT, 3, 1, ANGLE, FP_ANY, "Feed-forward attitude: the guidance's mu_c for a vehicle exactly on the shaped reference (the shaped mu_ref where that is feasible)") \
    X(mu_rate_ff, 2125, REAL, OUTPUT, 3, 1, ANGULAR_VELOCITY, FP_ANY, "Euler-rate feed-forward of the attitude loop: the rate of mu_ff") \
    X(ref_acc_limit, 2128, REAL, OUTPUT, 2, 1, ACCELERATION, FP_ANY, "Acceleration limits the shaping uses [horizontal, vertical] (ref_acc_max, or derived)") \
    X(ref_vel_limit, 2150, REAL, OUTPUT, 2, 1, VELOCITY, FP_ANY, "Speed limits the shaping uses [horizontal, vertical] (ref_vel_max, or derived)") \
    X(ref_jerk_limit, 2152, REAL, OUTPUT, 2, 1, JERK, FP_ANY, "Jerk limits the shaping uses [horizontal, vertical] (ref_jerk_max, or derived)") \
    X(ref_att_rate_limit, 2154, REAL, OUTPUT, 3, 1, ANGULAR_VELOCITY, FP_ANY, "Euler-rate limits the shaping uses [roll, pitch, heading] (ref_att_rate_max, or derived)") \
    X(ref_att_acc_limit, 2157, REAL, OUTPUT, 3, 1, ANGULAR_ACCELERATION, FP_ANY, "Euler-acceleration limits the shaping uses [roll, pitch, heading] (ref_att_acc_max, or derived)") \
    X(rotor_eff_est, 2130, REAL, OUTPUT, 8, 1, RATIO, FP_ANY, "Rotor efficiencies the detector estimates (1 until it detects a fault; below 0.15: lost, idled at a probe speed and restored when its thrust shows at 0.3 or more)") \
    X(rotors_detected, 2140, INTEGER, OUTPUT, 1, 1, NONE, FP_ANY, "Rotors the detector found faulty: bit i-1 rotor i") \
    X(indi_residual, 2141, REAL, OUTPUT, 6, 1, WRENCH, FP_ANY, "INDI residual: measured minus modelled rotor wrench [f_b (N); tau_b (N.m)], body") \
    X(landed, 2160, BOOLEAN, OUTPUT, 1, 1, NONE, FP_ANY, "On the ground: it carries half the weight or more while the vehicle is at rest (docs/controller.md, \"On the ground\")") \
    X(idle, 2161, BOOLEAN, OUTPUT, 1, 1, NONE, FP_ANY, "The rotors idle: disarmed, or landed with the reference not above the vehicle") \
    X(ground_support, 2162, REAL, OUTPUT, 1, 1, FORCE, FP_ANY, "Upward force of the ground on the vehicle, estimated: m g + (R f_b)_z - m a_z")

/* What each output is a function of at initialization (the format and its rules:
 * PLANT_INITIAL_DEPENDENCIES in plant/plant_vars.h).  controller.c controller_initialize sets
 * them; no sample has run. */
#define CTRL_AIRFRAME FP_AIRFRAME_VARIABLES(FP_AIRFRAME_NAME, 1)
#define CTRL_FORCE_SET "poly_n poly_A poly_b poly_margin "
#define CONTROLLER_INITIAL_DEPENDENCIES(D)                                                       \
    /* the commands hold the measured actuator state; f_b_c, f_b_ref: the force it gives */      \
    D("omega_cmd alpha_cmd beta_cmd", "n_rotors omega alpha beta")                               \
    D("f_b_ref f_b_c", CTRL_AIRFRAME "omega alpha beta")                                         \
    /* the references as given (no jump being shaped; the heading unwrapped from its own) */     \
    D("mu_c pos_ref_s vel_ref_s acc_ref_s euler_ref_s mu_ff mu_rate_ff",                         \
      "pos_ref euler_ref vel_ref acc_ref euler_rate_ref")                                        \
    /* the rotors the importer reports lost, the force sets in use and their hover flags */      \
    D("rotors_lost active_polytope hover_possible",                                              \
      CTRL_AIRFRAME CTRL_FORCE_SET "fail_poly_n fail_poly_A fail_poly_b fault_detect "           \
                                   "rotor_health")                                               \
    /* the shaping's limits, given or derived: translation from the nominal force set, */        \
    /* attitude from the rotors' torque at the hover trim (shaping_limits.c) */                  \
    D("ref_acc_limit ref_vel_limit ref_jerk_limit",                                              \
      CTRL_AIRFRAME CTRL_FORCE_SET "ref_bandwidth ref_tilt_max ref_vel_max ref_acc_max "         \
                                   "ref_jerk_max ref_att_rate_max")                              \
    D("ref_att_rate_limit ref_att_acc_limit", CTRL_AIRFRAME "ref_att_rate_max ref_att_acc_max")  \
    /* nothing solved or detected yet: feasible, zeros (statuses, counts, times), 1s */          \
    D("feasible guid_status guid_iter alloc_status alloc_iter sat_flags guid_flags acc_c "       \
      "rate_c dnu_c alloc_residual t_step t_guid t_alloc rotor_eff_est rotors_detected "         \
      "indi_residual", "")                                                                      \
    /* what the ground carries at the start: the measured acceleration against the rotors' */   \
    /* force; nothing idles before the first sample */                                          \
    D("landed ground_support", CTRL_AIRFRAME "acc vel euler omega alpha beta rotor_health")      \
    D("idle", "")

#endif
