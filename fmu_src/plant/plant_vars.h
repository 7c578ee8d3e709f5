/*
 * MultirotorPlant: THE variable table.  modelDescription.xml (tools/mdgen.c),
 * the FMI get/set dispatch (common/fmi2_values.c) and the model's own range
 * checks are all generated from it; a row's name is also the PlantModel member
 * that holds the value.
 *
 * X(name, value reference, type, kind, rows, cols, declared type, range, description)
 * XAF: the same for the rows of the airframe table both FMUs share (common/airframe_vars.h),
 * whose members live in the model's `af` (an FpAirframe).
 * XS: the same for the Model Exchange rows (kind STATE or DERIVATIVE, fp_model.h), which
 * name parts of one vector member, with two more columns: the member (x, the state; der_x,
 * its derivative) and the index of the part's first element in it (PLANT_X_POS, ...,
 * plant.h).  The state rows cover x in order (the order of fmi2GetContinuousStates), each
 * with its derivative row "der_<name>".
 *
 * - declared type: the physical kind of a Real (FP_DECLARED_TYPES in
 *   common/fp_model.h: its quantity, unit and nominal), NONE otherwise.
 * - range: FP_ANY, FP_POSITIVE (> 0), FP_NONNEGATIVE (>= 0), FP_IN(a, b)
 *   [a, b], FP_IN_OPEN(a, b) (a, b), FP_IN_LOPEN(a, b) (a, b].  It is the
 *   declared min/max and the bound the model checks (plant.c validate and
 *   check_inputs, common/fp_params.c), so a changed range changes both; FMI's
 *   min and max are inclusive, so an open bound is declared at the nearest
 *   double inside it, the first value the check accepts (common/fp_model.h).
 *   Entries beyond n_rotors are ignored and not checked.  Commands (omega_cmd,
 *   alpha_cmd, beta_cmd) have no range: beyond the actuator limits they are
 *   saturated, which is the hardware's physics.
 *
 * Value references are stable: append, never renumber.
 */
#ifndef PLANT_VARS_H
#define PLANT_VARS_H

#include "airframe_vars.h"

#define PLANT_VARIABLES(X, XAF, XS)                                                                      \
    /* parameters: the airframe (common/airframe_vars.h) */                                      \
    FP_AIRFRAME_VARIABLES(XAF, 0)                                                                  \
    X(h_internal, 114, REAL, PARAM_FIXED, 1, 1, TIME, FP_POSITIVE, "Internal RK4 step; a communication step h takes ceil(h / h_internal) equal RK4 steps") \
    /* parameters: initial state */                                                                \
    X(pos0, 120, REAL, PARAM_FIXED, 3, 1, LENGTH, FP_ANY, "Initial position, world NED")           \
    X(vel0, 123, REAL, PARAM_FIXED, 3, 1, VELOCITY, FP_ANY, "Initial velocity, world NED")         \
    X(euler0, 126, REAL, PARAM_FIXED, 3, 1, ANGLE, FP_ANY, "Initial attitude [phi, theta, psi], R_B^W = Rz(psi) Ry(theta) Rx(phi)") \
    X(rate0, 129, REAL, PARAM_FIXED, 3, 1, ANGULAR_VELOCITY, FP_ANY, "Initial body rates [p, q, r]") \
    X(init_trim, 132, BOOLEAN, PARAM_FIXED, 1, 1, NONE, FP_ANY, "Start the actuators at hover trim for euler0 (ignores omega0, alpha0, beta0)") \
    X(omega0, 140, REAL, PARAM_FIXED, 8, 1, ROTOR_SPEED, FP_NONNEGATIVE, "Initial rotor speeds (when init_trim is false)") \
    X(alpha0, 150, REAL, PARAM_FIXED, 8, 1, ANGLE, FP_IN(-FP_SERVO_LIMIT, FP_SERVO_LIMIT), "Initial servo angles alpha (when init_trim is false)") \
    X(beta0, 160, REAL, PARAM_FIXED, 8, 1, ANGLE, FP_IN(-FP_SERVO_LIMIT, FP_SERVO_LIMIT), "Initial servo angles beta (when init_trim is false)") \
    /* parameters: sensor noise (all zero: off) */                                                 \
    X(noise_seed, 170, INTEGER, PARAM_FIXED, 1, 1, NONE, FP_ANY, "Seed of the sensor-noise generator") \
    X(noise_pos, 171, REAL, PARAM_FIXED, 1, 1, LENGTH, FP_NONNEGATIVE, "Standard deviation of position noise") \
    X(noise_vel, 172, REAL, PARAM_FIXED, 1, 1, VELOCITY, FP_NONNEGATIVE, "Standard deviation of velocity noise") \
    X(noise_acc, 173, REAL, PARAM_FIXED, 1, 1, ACCELERATION, FP_NONNEGATIVE, "Standard deviation of acceleration noise") \
    X(noise_att, 174, REAL, PARAM_FIXED, 1, 1, ANGLE, FP_NONNEGATIVE, "Standard deviation of Euler-angle noise") \
    X(noise_rate, 175, REAL, PARAM_FIXED, 1, 1, ANGULAR_VELOCITY, FP_NONNEGATIVE, "Standard deviation of body-rate noise") \
    X(noise_ang_acc, 176, REAL, PARAM_FIXED, 1, 1, ANGULAR_ACCELERATION, FP_NONNEGATIVE, "Standard deviation of angular-acceleration noise") \
    X(timing, 177, BOOLEAN, PARAM_FIXED, 1, 1, NONE, FP_ANY, "Measure the computation time of each step (t_step); off keeps runs bit-reproducible") \
    /* parameters: sensor timing (all zero: every output exact and current) */              \
    X(mocap_period, 178, REAL, PARAM_FIXED, 1, 1, TIME, FP_IN(0, 1), "Sample period of the pose measurements pos, vel, euler, quat (motion capture, e.g. 1/120 s); held between samples; 0: every communication point") \
    X(mocap_delay, 179, REAL, PARAM_FIXED, 1, 1, TIME, FP_IN(0, 0.5), "Latency of the pose measurements: each sample shows the state this long before it (linear between communication points)") \
    X(imu_period, 180, REAL, PARAM_FIXED, 1, 1, TIME, FP_IN(0, 1), "Sample period of the inertial measurements acc, rate, ang_acc; held between samples; 0: every communication point") \
    /* parameters: ground contact of the landing gear (plant/contact.h; n_contacts 0: none) */ \
    X(n_contacts, 181, INTEGER, PARAM_FIXED, 1, 1, NONE, FP_IN(0, 8), "Contact points of the landing gear in use (0..8; 0: no ground)") \
    X(ground_z, 182, REAL, PARAM_FIXED, 1, 1, LENGTH, FP_ANY, "World z of the flat ground (NED: the ground is below the vehicle at larger z)") \
    X(contact_stiffness, 183, REAL, PARAM_FIXED, 1, 1, STIFFNESS, FP_POSITIVE, "Contact stiffness k of each point: normal force k d at penetration d") \
    X(contact_damping, 184, REAL, PARAM_FIXED, 1, 1, DAMPING, FP_NONNEGATIVE, "Contact damping c of each point: normal force adds c times the downward speed (never pulls)") \
    X(contact_friction, 185, REAL, PARAM_FIXED, 1, 1, DIMENSIONLESS, FP_NONNEGATIVE, "Coulomb friction coefficient mu of each point against the ground") \
    X(contact_pos, 400, REAL, PARAM_FIXED, 8, 3, LENGTH, FP_ANY, "Contact points of the landing gear in the body frame FRD (row i = point i)") \
    /* inputs */                                                                                   \
    X(omega_cmd, 200, REAL, INPUT, 8, 1, ROTOR_SPEED, FP_ANY, "Commanded rotor speeds (saturated at the limits, see sat_flags)") \
    X(alpha_cmd, 210, REAL, INPUT, 8, 1, ANGLE, FP_ANY, "Commanded servo angles alpha")            \
    X(beta_cmd, 220, REAL, INPUT, 8, 1, ANGLE, FP_ANY, "Commanded servo angles beta")              \
    X(efficiency, 230, REAL, INPUT, 8, 1, RATIO, FP_IN(0, 1), "Rotor efficiency 0..1 scaling thrust and drag (1 healthy, 0 lost)") \
    X(f_d, 240, REAL, INPUT, 3, 1, FORCE, FP_ANY, "Disturbance force f_d, world NED")              \
    X(tau_d, 243, REAL, INPUT, 3, 1, TORQUE, FP_ANY, "Disturbance torque tau_d, body FRD")         \
    X(a_d, 246, REAL, INPUT, 3, 1, ACCELERATION, FP_ANY, "Disturbance acceleration, world NED")    \
    /* outputs */                                                                                  \
    X(pos, 300, REAL, OUTPUT, 3, 1, LENGTH, FP_ANY, "Position xi, world NED")                      \
    X(vel, 303, REAL, OUTPUT, 3, 1, VELOCITY, FP_ANY, "Velocity, world NED")                       \
    X(acc, 306, REAL, OUTPUT, 3, 1, ACCELERATION, FP_ANY, "Acceleration (second derivative of position), world NED") \
    X(euler, 309, REAL, OUTPUT, 3, 1, ANGLE, FP_ANY, "Attitude [phi, theta, psi]")                 \
    X(quat, 312, REAL, OUTPUT, 4, 1, DIMENSIONLESS, FP_ANY, "Attitude quaternion [w, x, y, z] of R_B^W, w >= 0") \
    X(rate, 316, REAL, OUTPUT, 3, 1, ANGULAR_VELOCITY, FP_ANY, "Body rates Omega = [p, q, r]")     \
    X(ang_acc, 319, REAL, OUTPUT, 3, 1, ANGULAR_ACCELERATION, FP_ANY, "Angular acceleration dOmega/dt, body FRD") \
    X(omega, 330, REAL, OUTPUT, 8, 1, ROTOR_SPEED, FP_ANY, "Measured rotor speeds")                \
    X(alpha, 340, REAL, OUTPUT, 8, 1, ANGLE, FP_ANY, "Measured servo angles alpha")                \
    X(beta, 350, REAL, OUTPUT, 8, 1, ANGLE, FP_ANY, "Measured servo angles beta")                  \
    X(f_b, 360, REAL, OUTPUT, 3, 1, FORCE, FP_ANY, "Rotor force f_b in the body frame")            \
    X(tau_b, 363, REAL, OUTPUT, 3, 1, TORQUE, FP_ANY, "Rotor torque tau_b in the body frame")      \
    X(sat_flags, 370, INTEGER, OUTPUT, 1, 1, NONE, FP_ANY, "Commands beyond limits in the last step: bit i-1 motor i, bit 7+i alpha i, bit 15+i beta i") \
    X(t_step, 371, REAL, OUTPUT, 1, 1, TIME, FP_ANY, "Computation time of the last doStep (0 unless timing)") \
    /* outputs: the true state beside the measured one (equal to it with the noise off) */    \
    X(pos_true, 380, REAL, OUTPUT, 3, 1, LENGTH, FP_ANY, "True position, world NED (pos without sensor noise)") \
    X(vel_true, 383, REAL, OUTPUT, 3, 1, VELOCITY, FP_ANY, "True velocity, world NED (vel without sensor noise)") \
    X(euler_true, 386, REAL, OUTPUT, 3, 1, ANGLE, FP_ANY, "True attitude [phi, theta, psi] (euler without sensor noise)") \
    X(quat_true, 389, REAL, OUTPUT, 4, 1, DIMENSIONLESS, FP_ANY, "True attitude quaternion [w, x, y, z] of R_B^W, w >= 0") \
    X(rate_true, 393, REAL, OUTPUT, 3, 1, ANGULAR_VELOCITY, FP_ANY, "True body rates (rate without sensor noise)") \
    X(pose_age, 396, REAL, OUTPUT, 1, 1, TIME, FP_ANY, "Age of pos, vel, euler, quat: the time since the state they show (mocap_delay plus the time since their sample; 0 with ideal sensors)") \
    /* outputs: ground contact */                                                                  \
    X(contact_force, 430, REAL, OUTPUT, 8, 1, FORCE, FP_ANY, "Normal force of each contact point on the ground (0: not touching)") \
    X(contact_flags, 438, INTEGER, OUTPUT, 1, 1, NONE, FP_ANY, "Contact points below the ground surface: bit i-1 point i") \
    X(landed, 439, BOOLEAN, OUTPUT, 1, 1, NONE, FP_ANY, "Every contact point in use touches the ground") \
    X(contact_depth, 440, REAL, LOCAL, 8, 1, LENGTH, FP_ANY, "Depth of each contact point below the ground (negative above it; -1 for the points beyond n_contacts): the event indicators of Model Exchange, where the contact force switches on and off") \
    /* Model Exchange: the continuous state (vr 500 + its index in x) and its derivative     \
     * (600 + index); in co-simulation the state at the communication point and the         \
     * derivative there (the same function of the state and the inputs held) */             \
    XS(x_pos, 500, REAL, STATE, 3, 1, LENGTH, FP_ANY, "State: position, world NED", x, PLANT_X_POS) \
    XS(x_vel, 503, REAL, STATE, 3, 1, VELOCITY, FP_ANY, "State: velocity, world NED", x, PLANT_X_VEL) \
    XS(x_quat, 506, REAL, STATE, 4, 1, DIMENSIONLESS, FP_ANY, "State: attitude quaternion [w, x, y, z] of R_B^W (in co-simulation renormalized after every RK4 step with w >= 0; in Model Exchange the solver's)", x, PLANT_X_QUAT) \
    XS(x_rate, 510, REAL, STATE, 3, 1, ANGULAR_VELOCITY, FP_ANY, "State: body rates [p, q, r]", x, PLANT_X_RATE) \
    XS(x_omega, 513, REAL, STATE, 8, 1, ROTOR_SPEED, FP_ANY, "State: rotor speeds (rotors beyond n_rotors: 0, derivative 0)", x, PLANT_X_OMEGA) \
    XS(x_alpha, 521, REAL, STATE, 8, 1, ANGLE, FP_ANY, "State: servo angles alpha", x, PLANT_X_ALPHA) \
    XS(x_beta, 529, REAL, STATE, 8, 1, ANGLE, FP_ANY, "State: servo angles beta", x, PLANT_X_BETA) \
    XS(der_x_pos, 600, REAL, DERIVATIVE, 3, 1, VELOCITY, FP_ANY, "Derivative of x_pos", der_x, PLANT_X_POS) \
    XS(der_x_vel, 603, REAL, DERIVATIVE, 3, 1, ACCELERATION, FP_ANY, "Derivative of x_vel (acc without sensor effects)", der_x, PLANT_X_VEL) \
    XS(der_x_quat, 606, REAL, DERIVATIVE, 4, 1, DIMENSIONLESS_RATE, FP_ANY, "Derivative of x_quat", der_x, PLANT_X_QUAT) \
    XS(der_x_rate, 610, REAL, DERIVATIVE, 3, 1, ANGULAR_ACCELERATION, FP_ANY, "Derivative of x_rate (ang_acc without sensor effects)", der_x, PLANT_X_RATE) \
    XS(der_x_omega, 613, REAL, DERIVATIVE, 8, 1, ANGULAR_ACCELERATION, FP_ANY, "Derivative of x_omega: (saturated omega_cmd - omega) / tau_motor", der_x, PLANT_X_OMEGA) \
    XS(der_x_alpha, 621, REAL, DERIVATIVE, 8, 1, ANGULAR_VELOCITY, FP_ANY, "Derivative of x_alpha: (saturated alpha_cmd - alpha) / tau_servo", der_x, PLANT_X_ALPHA) \
    XS(der_x_beta, 629, REAL, DERIVATIVE, 8, 1, ANGULAR_VELOCITY, FP_ANY, "Derivative of x_beta: (saturated beta_cmd - beta) / tau_servo", der_x, PLANT_X_BETA)

/*
 * What each output is a function of at initialization: the dependencies of its entry in the
 * modelDescription's <InitialUnknowns> (tools/mdgen.c; FMI 2.0 section 2.2.8: the knowns are
 * the inputs and the parameters, initial="exact").  D(outputs, knowns): row names separated by
 * spaces, FP_ALL_PARAMETERS for every parameter.  Every output row is in exactly one
 * declaration (the build fails otherwise); "" declares an output constant at t0.  A list may
 * be conservative (name a known some of its outputs ignore), never short:
 * tests/test_fmus/test_model_structure.py perturbs the knowns one by one and fails on any
 * initial output that moves with a known its declaration leaves out.
 *
 * The actuator commands are no known of any output: at t0 they only set the actuators'
 * derivatives (the state starts at init_trim's hover trim or omega0, alpha0, beta0), so the
 * plant's initial outputs never wait for the controller's (no algebraic loop for a master).
 */
#define PLANT_INITIAL_STATE                                                                      \
    "pos0 vel0 euler0 rate0 noise_seed noise_pos noise_vel noise_acc noise_att noise_rate "     \
    "noise_ang_acc mocap_period mocap_delay imu_period "
#define PLANT_INITIAL_DEPENDENCIES(D)                                                            \
    /* the initial pose and rates and their measurements (noise, sampling, latency) */          \
    D("pos vel euler quat rate pos_true vel_true euler_true quat_true rate_true pose_age",       \
      PLANT_INITIAL_STATE)                                                                       \
    /* the actuators at init_trim's hover trim for euler0, or at omega0, alpha0, beta0 */        \
    D("omega alpha beta", FP_AIRFRAME_VARIABLES(FP_AIRFRAME_NAME, 0)                             \
      "euler0 init_trim omega0 alpha0 beta0")                                                    \
    /* the rotor wrench (efficiency) and the accelerations it gives with the disturbances */     \
    D("acc ang_acc f_b tau_b", FP_ALL_PARAMETERS "efficiency f_d tau_d a_d")                     \
    /* no step yet: no saturation, no timing */                                                  \
    D("sat_flags t_step", "")                                                                    \
    /* the landing gear against the ground at the initial pose and velocity */                  \
    D("contact_force contact_flags landed", FP_ALL_PARAMETERS)                                   \
    /* Model Exchange: the initial state, and its derivative (which the commands do set) */    \
    D("x_pos x_vel x_quat x_rate", "pos0 vel0 euler0 rate0")                                    \
    D("x_omega x_alpha x_beta", FP_AIRFRAME_VARIABLES(FP_AIRFRAME_NAME, 0)                       \
      "euler0 init_trim omega0 alpha0 beta0")                                                    \
    D("der_x_pos der_x_vel der_x_quat der_x_rate der_x_omega der_x_alpha der_x_beta",           \
      FP_ALL_PARAMETERS "omega_cmd alpha_cmd beta_cmd efficiency f_d tau_d a_d")

/*
 * What each output is a function of in Model Exchange: the dependencies of its entry in the
 * modelDescription's <Outputs> (FMI 2.0 section 2.2.8: the knowns are the inputs and the
 * continuous states).  O(outputs, knowns): row names, "@states" for every state row; every
 * output in exactly one declaration.  In co-simulation no output depends on an input at a
 * communication point (outputs are computed at the end of a step, from the inputs held over
 * it): the input dependencies below are Model Exchange's, a conservative statement for
 * co-simulation.  tests/test_fmus/test_model_exchange.py perturbs the states and the inputs
 * one by one and fails on any output that moves with a known its declaration leaves out.
 */
#define PLANT_OUTPUT_DEPENDENCIES(O)                                                             \
    O("pos pos_true", "x_pos")                                                                   \
    O("vel vel_true", "x_vel")                                                                   \
    O("euler quat euler_true quat_true", "x_quat")                                               \
    O("rate rate_true", "x_rate")                                                                \
    O("omega", "x_omega")                                                                        \
    O("alpha", "x_alpha")                                                                        \
    O("beta", "x_beta")                                                                          \
    /* the rotor wrench (efficiency scales it), the contact (pose, velocity, rates), f_d, a_d */ \
    O("acc", "@states efficiency f_d a_d")                                                       \
    O("ang_acc", "@states efficiency tau_d")                                                     \
    O("f_b tau_b", "x_omega x_alpha x_beta efficiency")                                          \
    /* the commands beyond the limits (Model Exchange: the commands set now) */                 \
    O("sat_flags", "omega_cmd alpha_cmd beta_cmd")                                               \
    O("t_step pose_age", "")                                                                     \
    O("contact_force contact_flags landed", "x_pos x_vel x_quat x_rate")

#endif
