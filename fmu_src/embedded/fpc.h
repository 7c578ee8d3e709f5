/*
 * fpc: the FullPoseController's C core for a flight controller, without FMI.
 *
 * The same model code as the controller FMU (controller/, common/), behind a small API a
 * firmware task calls at the sample rate:
 *
 *     static FpcController ctrl;                        // no heap: the caller owns it
 *     fpc_defaults(&ctrl, log_fn, log_env);             // every parameter at its default
 *     fpc_set_reals(&ctrl, "mass", &mass, 1);           // parameters by the FMU's names
 *     fpc_start(&ctrl, t0, &inputs);                    // checks them, starts from inputs
 *     every Ts: fpc_step(&ctrl, t0 + k * Ts, &inputs, &outputs);
 *
 * Names, value references, units, ranges and defaults are the controller FMU's
 * (controller/controller_vars.h; docs/fmus.md lists them), so a parameter set that
 * initializes the FMU initializes this, and a sample computes what the FMU's sample
 * computes from the same inputs.  Every function returns FP_OK, or FP_WARNING (usable,
 * something was said), or FP_ERROR with the reason given to the log function (naming the
 * parameter or input); an FP_ERROR changes none of the controller's state (inputs passed
 * to a refused fpc_step stay set, as an FMU's inputs do).
 *
 * Nothing here allocates, and no function keeps state outside its FpcController.  The
 * sample path calls libm only; text (snprintf) is formatted when something is said.  A
 * timing build (the parameter `timing`) reads the board's clock through fp_clock_seconds()
 * (common/fp_clock.h), which the board provides.
 */
#ifndef FPC_H
#define FPC_H

#include <stddef.h>
#include <stdint.h>

#include "controller.h"

#define FPC_MAX_ROTORS FP_MAX_ROTORS

/* What the controller reads each sample: the references and the measured state.  Per-rotor
 * arrays hold the airframe's n_rotors first (the rest ignored).  Angles in rad, SI units,
 * world frame NED as the FMU's inputs. */
typedef struct {
    double pos_ref[3], euler_ref[3], vel_ref[3], acc_ref[3], euler_rate_ref[3];
    double rotor_health[FPC_MAX_ROTORS]; /* the efficiency each rotor is told to have, 0..1 */
    double pos[3], vel[3], acc[3], euler[3], rate[3];
    double omega[FPC_MAX_ROTORS], alpha[FPC_MAX_ROTORS], beta[FPC_MAX_ROTORS];
    double pose_age; /* s: how old the pose measurement is at the sample (0: fresh) */
    int32_t armed;   /* 0: rotors idle, the land detector's ground behaviour */
} FpcInputs;

/* What a sample commands, and what a firmware logs beside it. */
typedef struct {
    double omega_cmd[FPC_MAX_ROTORS], alpha_cmd[FPC_MAX_ROTORS], beta_cmd[FPC_MAX_ROTORS];
    double mu_c[3];    /* commanded roll, pitch, heading (rad) */
    double f_b_ref[3]; /* the guidance's body force (N) */
    int32_t feasible, guid_status, alloc_status, rotors_lost, landed, idle;
} FpcOutputs;

/* Receives every message: status FP_OK (information), FP_WARNING or FP_ERROR, and the text.
 * NULL: messages are dropped (the status still says what happened). */
typedef void (*FpcLogFn)(void *env, FpStatus status, const char *message);

/* The controller and everything it needs.  Its size is fixed (sizeof(FpcController)): a
 * firmware places it statically. */
typedef struct {
    ControllerModel model;
    FpLogger logger;
    FpcLogFn log;
    void *log_env;
    double t_next;   /* the instant the next sample is due (started) */
    int32_t started; /* fpc_start succeeded */
    int32_t changed; /* a tunable parameter changed since the last sample */
} FpcController;

/* Every variable at the controller FMU's start value; not started. */
FpStatus fpc_defaults(FpcController *c, FpcLogFn log, void *log_env);

/*
 * The value reference of element 0 of the variable called name, and its element count,
 * type (FP_REAL, FP_INTEGER, FP_BOOLEAN) and kind: FP_ERROR (said) for an unknown name.
 * Any pointer but c and name may be NULL.
 */
FpStatus fpc_find(const FpcController *c, const char *name, uint32_t *vr, uint32_t *count,
                  FpVarType *type, FpVarKind *kind);

/*
 * Set n elements of the variable called name from element 0 (n: at most its element count):
 * Real variables with fpc_set_reals, Integer and Boolean (0 or 1) with fpc_set_ints.
 * Fixed parameters before fpc_start only; tunable parameters and inputs at any time (a
 * tunable change is checked at the next sample, as the FMU's); outputs never.
 */
FpStatus fpc_set_reals(FpcController *c, const char *name, const double *values, size_t n);
FpStatus fpc_set_ints(FpcController *c, const char *name, const int32_t *values, size_t n);

/* The same by value references (vr[i]: one element each), as an FMU's fmi2SetReal: nothing
 * is written unless every element may be. */
FpStatus fpc_set_reals_vr(FpcController *c, const uint32_t *vr, size_t n, const double *values);
FpStatus fpc_set_ints_vr(FpcController *c, const uint32_t *vr, size_t n, const int32_t *values);
/* Any variable's current values by value references (Integer and Boolean as int32). */
FpStatus fpc_get_reals_vr(const FpcController *c, const uint32_t *vr, size_t n, double *values);
FpStatus fpc_get_ints_vr(const FpcController *c, const uint32_t *vr, size_t n, int32_t *values);

/*
 * Check the parameters, derive what the samples need (force sets, limits, filters) and
 * start the states from the inputs (in: NULL keeps those set by value reference), as the
 * FMU's initialization at t0.  The first sample is due at t0.
 */
FpStatus fpc_start(FpcController *c, double t0, const FpcInputs *in);

/*
 * One sample at t = t0 + k Ts from these inputs (in: NULL keeps those set by value
 * reference); out (NULL: not copied) gets the commands.  A t off the sample grid, or any
 * but the next instant due, is FP_ERROR.  A sample whose inputs are unusable holds the last
 * commands and says why (FP_WARNING), as the FMU does.
 */
FpStatus fpc_step(FpcController *c, double t, const FpcInputs *in, FpcOutputs *out);

/* The commands and diagnostics of the last sample. */
void fpc_outputs(const FpcController *c, FpcOutputs *out);

#endif
