/*
 * Ground contact of the landing gear: a compliant contact at each of up to PLANT_MAX_CONTACTS
 * points fixed in the body, against a flat ground at world z = ground_z (NED: the ground lies
 * below the vehicle at larger z).
 *
 * At a point whose world position lies below the ground by d > 0 (penetration), moving at
 * the world velocity v:
 *
 *   normal force     F_n = max(0, k d + c v_z)                 upward (-z), never pulling;
 *   friction         F_t = -(k s + c v_t), at most mu F_n long  along the ground,
 *
 * with v_t the point's velocity along the ground and s its displacement along the ground from
 * its anchor: where it touched down, moved only when the point slips.  A point sticks while
 * |k s + c v_t| <= mu F_n: friction then holds it elastically (s = F_t / k, a fraction of a
 * millimetre), so a push below mu m g moves nothing (Coulomb's static friction, no creep).
 * Beyond it the point slides with friction mu F_n, and its anchor is dragged along so that
 * k |s| never exceeds mu F_n (an elasto-plastic contact, updated after every internal step:
 * contact_update_anchors).  The same k and c act along and normal to the ground.
 */
#ifndef PLANT_CONTACT_H
#define PLANT_CONTACT_H

#include <stdint.h>

#define PLANT_MAX_CONTACTS 8
/* the largest |lambda| h_internal the plant accepts for its contact (RK4's real-axis limit
 * is 2.79) */
#define PLANT_CONTACT_RATE_STEP 2.5

typedef struct {
    int n;                     /* contact points in use (0: no ground) */
    const double *pos;         /* their positions in the body frame (FRD), m: point i at 3 i */
    double ground_z;           /* world z of the ground (NED), m */
    double stiffness;          /* k, N/m per point */
    double damping;            /* c, N s/m per point */
    double friction;           /* mu */
    double mass;               /* the vehicle's mass and inverse inertia (body) */
    const double *inertia_inv; /* 3 x 3, row-major */
    const double *anchor;      /* each point's anchor on the ground (world x, y): 2 i */
    int32_t anchored;          /* bit i: point i+1 has an anchor (it touched down) */
} ContactParams;

typedef struct {
    double force_w[3];                  /* total contact force, world frame, N */
    double torque_b[3];                 /* total contact torque about the CoG, body frame, N m */
    double normal[PLANT_MAX_CONTACTS];  /* F_n of each point, N */
    int32_t flags;                      /* bit i: point i+1 below the ground (d > 0) */
} ContactWrench;

/* The contact wrench at the state (pos, vel: world; r: R_B^W, 3 x 3 row-major; rate: body
 * rates). */
void contact_wrench(const ContactParams *p, const double pos[3], const double vel[3],
                    const double *r, const double rate[3], ContactWrench *out);

/* The deepest point below the ground at the pose (its index, 0-based; -1 for none below)
 * and its penetration into depth. */
int contact_deepest(const ContactParams *p, const double pos[3], const double *r,
                    double *depth);

/* Each point's depth below the ground at the pose (> 0: below, < 0: above), into depth[0 ..
 * n - 1]: where it changes sign the contact force switches on or off (Model Exchange's event
 * indicators). */
void contact_depths(const ContactParams *p, const double pos[3], const double *r, double *depth);

/*
 * After an internal step, at the new state: the anchors of the points touching (a new one
 * where a point touched down, dragged along where a point slips, dropped where it lifted
 * off), into anchor (2 per point) and the returned bitmask.
 */
int32_t contact_update_anchors(const ContactParams *p, const double pos[3], const double *r,
                               double *anchor);

/*
 * An upper bound of the fastest contact mode's rate |lambda| (1/s) with every point touching
 * at the upright pose, along the worst of the world axes: the trace bounds
 * sum_i c w_i + sqrt(sum_i k w_i), w_i the apparent inverse mass of point i along the axis.
 * RK4 is stable for |lambda| h below about 2.8 (the plant asks for PLANT_CONTACT_RATE_STEP).
 */
double contact_fastest_rate(const ContactParams *p);

#endif
