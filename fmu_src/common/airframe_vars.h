/*
 * The airframe: THE variable table both FMUs share (the format of plant/plant_vars.h).  Each
 * FMU's table includes it, the rows' members are those of FpAirframe (common/multirotor.h),
 * which both models embed as `af`, and fp_check_airframe (common/fp_params.c) validates them
 * by these rows' ranges in both FMUs alike: the airframe has one home.
 *
 * FP_AIRFRAME_VARIABLES(X, S): S shifts the value references of the first six rows (the
 * plant numbers them from 1, the controller from 2, after its Ts; value references are
 * stable: append, never renumber).  The controller's INDI uses mass and inertia as its
 * nominal model; it keeps tau_motor and tau_servo for design tools (the actuator lag its
 * gains are certified for, docs/robust_design.md) and checks them like the plant.
 */
#ifndef FP_AIRFRAME_VARS_H
#define FP_AIRFRAME_VARS_H

#include "multirotor.h"

#define FP_AIRFRAME_VARIABLES(X, S)                                                              \
    X(n_rotors, 1 + (S), INTEGER, PARAM_FIXED, 1, 1, NONE, FP_IN(1, FP_MAX_ROTORS), "Number of rotors in use (1..8); entries beyond it are ignored") \
    X(mass, 2 + (S), REAL, PARAM_FIXED, 1, 1, MASS, FP_POSITIVE, "Vehicle mass m (the controller: its nominal model, used by the INDI loops)") \
    X(inertia, 3 + (S), REAL, PARAM_FIXED, 3, 3, INERTIA, FP_ANY, "Inertia matrix I_B about the centre of gravity, body FRD axes (the controller: its nominal model)") \
    X(g, 12 + (S), REAL, PARAM_FIXED, 1, 1, ACCELERATION, FP_ANY, "Gravitational acceleration along world +z (down)") \
    X(k_t, 13 + (S), REAL, PARAM_FIXED, 1, 1, THRUST_COEFFICIENT, FP_POSITIVE, "Thrust coefficient: f_m = k_t omega^2") \
    X(k_d, 14 + (S), REAL, PARAM_FIXED, 1, 1, DRAG_COEFFICIENT, FP_NONNEGATIVE, "Drag-torque coefficient: tau_m = k_d omega^2") \
    X(rotor_pos, 20, REAL, PARAM_FIXED, 8, 3, LENGTH, FP_ANY, "Rotor positions d_i in the body frame (row i = rotor i)") \
    X(rotor_dir, 50, INTEGER, PARAM_FIXED, 8, 1, NONE, FP_IN(-1, 1), "Spin direction c_i (+1: reaction torque along the thrust, -1: against)") \
    X(rotor_gamma, 60, REAL, PARAM_FIXED, 8, 1, ANGLE, FP_ANY, "Fixed mounting angle gamma_i about body z (R_Mi^B = Rz(gamma) Rx(alpha) Ry(beta))") \
    X(alpha_min, 70, REAL, PARAM_FIXED, 8, 1, ANGLE, FP_IN(-FP_SERVO_LIMIT, FP_SERVO_LIMIT), "Lower limit of servo angle alpha_i (equal limits: fixed tilt)") \
    X(alpha_max, 80, REAL, PARAM_FIXED, 8, 1, ANGLE, FP_IN(-FP_SERVO_LIMIT, FP_SERVO_LIMIT), "Upper limit of servo angle alpha_i") \
    X(beta_min, 90, REAL, PARAM_FIXED, 8, 1, ANGLE, FP_IN(-FP_SERVO_LIMIT, FP_SERVO_LIMIT), "Lower limit of servo angle beta_i (equal limits: fixed tilt)") \
    X(beta_max, 100, REAL, PARAM_FIXED, 8, 1, ANGLE, FP_IN(-FP_SERVO_LIMIT, FP_SERVO_LIMIT), "Upper limit of servo angle beta_i") \
    X(omega_min, 110, REAL, PARAM_FIXED, 1, 1, ROTOR_SPEED, FP_NONNEGATIVE, "Lower limit of rotor speed") \
    X(omega_max, 111, REAL, PARAM_FIXED, 1, 1, ROTOR_SPEED, FP_POSITIVE, "Upper limit of rotor speed") \
    X(tau_motor, 112, REAL, PARAM_FIXED, 1, 1, TIME, FP_POSITIVE, "Time constant of the first-order motor model") \
    X(tau_servo, 113, REAL, PARAM_FIXED, 1, 1, TIME, FP_POSITIVE, "Time constant of the first-order servo model")

/* The airframe rows' names, "n_rotors mass ... tau_servo ": FP_AIRFRAME_VARIABLES(FP_AIRFRAME_NAME,
 * 0), for the InitialUnknowns declarations of the models' tables. */
#define FP_AIRFRAME_NAME(name, vr, type, kind, rows, cols, dtype, range, desc) #name " "

#endif
