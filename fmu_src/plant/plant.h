/* MultirotorPlant: 6-DoF rigid body of paper eq. (1)-(3) with first-order
 * actuators, integrated by fixed-step RK4. */
#ifndef PLANT_H
#define PLANT_H

#include <stdint.h>

#include "fp_model.h"
#include "contact.h"
#include "multirotor.h"

#define PLANT_NX (13 + 3 * FP_MAX_ROTORS) /* p, v, q, Omega, omega, alpha, beta */
/* The state vector x: where each part begins (plant_vars.h names the parts x_pos, ...). */
#define PLANT_X_POS 0
#define PLANT_X_VEL 3
#define PLANT_X_QUAT 6
#define PLANT_X_RATE 10
#define PLANT_X_OMEGA 13
#define PLANT_X_ALPHA (PLANT_X_OMEGA + FP_MAX_ROTORS)
#define PLANT_X_BETA (PLANT_X_ALPHA + FP_MAX_ROTORS)
/* Model Exchange: an event indicator per contact point (plant.c plant_event_indicators) */
#define PLANT_NZ PLANT_MAX_CONTACTS
#define PLANT_HISTORY 512 /* communication points of true pose kept for mocap_delay */

typedef struct {
    /* parameters */
    FpAirframe af; /* the airframe (common/airframe_vars.h) */
    double h_internal;
    double pos0[3], vel0[3], euler0[3], rate0[3];
    int32_t init_trim;
    double omega0[FP_MAX_ROTORS], alpha0[FP_MAX_ROTORS], beta0[FP_MAX_ROTORS];
    int32_t noise_seed;
    double noise_pos, noise_vel, noise_acc, noise_att, noise_rate, noise_ang_acc;
    int32_t timing;
    double mocap_period, mocap_delay, imu_period;
    int32_t n_contacts;
    double ground_z, contact_stiffness, contact_damping, contact_friction;
    double contact_pos[PLANT_MAX_CONTACTS][3];
    /* inputs */
    double omega_cmd[FP_MAX_ROTORS], alpha_cmd[FP_MAX_ROTORS], beta_cmd[FP_MAX_ROTORS];
    double efficiency[FP_MAX_ROTORS];
    double f_d[3], tau_d[3], a_d[3];
    /* outputs */
    double pos[3], vel[3], acc[3], euler[3], quat[4], rate[3], ang_acc[3];
    double omega[FP_MAX_ROTORS], alpha[FP_MAX_ROTORS], beta[FP_MAX_ROTORS];
    double f_b[3], tau_b[3];
    int32_t sat_flags;
    int32_t initialized; /* the glue's marker (FpModelInfo.initialized_offset); in padding */
    double t_step;
    double pos_true[3], vel_true[3], euler_true[3], quat_true[4], rate_true[3];
    double pose_age;
    double contact_force[PLANT_MAX_CONTACTS];
    int32_t contact_flags, landed;
    double contact_depth[PLANT_MAX_CONTACTS]; /* the event indicators (plant_vars.h) */
    /* internal state, derived at initialization */
    double x[PLANT_NX];
    double der_x[PLANT_NX]; /* dx/dt at the state and the inputs of the outputs' instant */
    double inertia_inv[3][3];
    FpRotorSet rotors;
    uint64_t rng[4];
    /* sensor timing: the true pose of the last PLANT_HISTORY communication points (ring),
     * the instants of the last pose and inertial samples */
    double hist_t[PLANT_HISTORY];
    double hist[PLANT_HISTORY][9]; /* pos, vel, euler */
    int32_t hist_head, hist_count;
    double t0, mocap_last, imu_last;
    /* ground contact: each touching point's anchor (world x, y; plant/contact.h) */
    double contact_anchor[PLANT_MAX_CONTACTS][2];
    int32_t contact_anchored;
    double contact_reach; /* the farthest contact point from the centre of gravity, m */
} PlantModel;

/* The plant model; its FMU returns it from fp_model_info(). */
const FpModelInfo *plant_model_info(void);

/* Exposed for the Python core library: the same defaults the FMU starts from. */
void plant_set_defaults(void *model);

#endif
