/*
 * ScenarioSignals: THE variable table (see plant/plant_vars.h for the columns).  Its outputs
 * are named like the inputs they feed: the controller's references and what it is told of the
 * rotors, the plant's disturbances and rotor efficiencies, so that an SSP connects them by
 * name.  Each output element plays the table column of its name (signals.c); an element
 * without a column holds its default (0, efficiencies and health 1).
 *
 * Value references are stable: append, never renumber.
 */
#ifndef SIGNALS_VARS_H
#define SIGNALS_VARS_H

#define SIGNALS_VARIABLES(X)                                                                    \
    /* the controller's references (its inputs of the same names) */                            \
    X(pos_ref, 1, REAL, OUTPUT, 3, 1, LENGTH, FP_ANY, "Reference position xi_ref, world NED")    \
    X(euler_ref, 4, REAL, OUTPUT, 3, 1, ANGLE, FP_ANY, "Reference attitude mu_ref")               \
    X(vel_ref, 7, REAL, OUTPUT, 3, 1, VELOCITY, FP_ANY, "Velocity feed-forward (derivative of pos_ref)") \
    X(acc_ref, 10, REAL, OUTPUT, 3, 1, ACCELERATION, FP_ANY, "Acceleration feed-forward (second derivative of pos_ref)") \
    X(euler_rate_ref, 13, REAL, OUTPUT, 3, 1, ANGULAR_VELOCITY, FP_ANY, "Euler-rate feed-forward (derivative of euler_ref)") \
    X(rotor_health, 16, REAL, OUTPUT, 8, 1, RATIO, FP_IN(0, 1), "What the controller is told of each rotor's efficiency 0..1") \
    /* the plant's disturbances and rotor efficiencies (its inputs of the same names) */        \
    X(f_d, 24, REAL, OUTPUT, 3, 1, FORCE, FP_ANY, "Disturbance force f_d, world NED")             \
    X(tau_d, 27, REAL, OUTPUT, 3, 1, TORQUE, FP_ANY, "Disturbance torque tau_d, body FRD")        \
    X(a_d, 30, REAL, OUTPUT, 3, 1, ACCELERATION, FP_ANY, "Disturbance acceleration, world NED")   \
    X(efficiency, 33, REAL, OUTPUT, 8, 1, RATIO, FP_IN(0, 1), "Rotor efficiency 0..1 (1 healthy, 0 lost)") \
    /* where the playback is */                                                                 \
    X(row, 41, INTEGER, OUTPUT, 1, 1, NONE, FP_ANY, "The table row the outputs hold (1-based): the last row whose time is at most the current time")

/* At initialization every output is the table's row at the start time: it depends on no
 * input or parameter (the table is a resource, not a variable). */
#define SIGNALS_INITIAL_DEPENDENCIES(D)                                                          \
    D("pos_ref euler_ref vel_ref acc_ref euler_rate_ref rotor_health f_d tau_d a_d efficiency " \
      "row", "")

#endif
