/*
 * The controller on the ground (stage "ground", before the cascade): what the ground
 * carries of the vehicle, whether it has landed, and whether the rotors idle.
 *
 * The ground's support is what the measured acceleration leaves unexplained by the rotors
 * and gravity: m a = R f_b + m g e_z + F_ground, so its upward part is
 * m g + (R f_b)_z - m a_z (NED), from the filtered signals the INDI loops use (both through
 * H(s), so they agree in time), computed by each sample for the next one's decision; from
 * the raw measurements at initialization and while the rotors idle.  In flight it is the vertical disturbance (zero without
 * one); resting on the gear with the rotors stopped it is the weight.  The vehicle has landed
 * once the ground carries half its weight or more while it is at rest (speed below
 * CTRL_LAND_SPEED) for CTRL_LAND_TIME, and has left the ground when the support falls under
 * a quarter of the weight.  The rotors idle when the vehicle is disarmed, or landed with the
 * reference not above it (no higher than CTRL_LAND_MARGIN above the measured position): a
 * landing ends with the rotors stopped, and a reference above starts a takeoff.
 */
#include <math.h>

#include "controller.h"
#include "stages.h"

double ctrl_ground_support(double mass, double g, const double r[9], const double f_b[3],
                           const double acc[3]) {
    double fz = r[6] * f_b[0] + r[7] * f_b[1] + r[8] * f_b[2]; /* (R f_b)_z */
    return mass * fabs(g) + fz - mass * acc[2];
}

void ctrl_ground(const CtrlGroundParams *p, const CtrlGroundInputs *in, CtrlGroundState *x,
                 CtrlGroundOut *out) {
    double weight = p->mass * fabs(p->g), speed;
    int need = (int)ceil(CTRL_LAND_TIME / p->Ts - 1e-9);
    speed = sqrt(in->vel[0] * in->vel[0] + in->vel[1] * in->vel[1] + in->vel[2] * in->vel[2]);
    if (in->support >= 0.5 * weight && speed < CTRL_LAND_SPEED) {
        if (x->carried < need) x->carried++;
    } else {
        x->carried = 0;
    }
    if (x->carried >= need) x->landed = 1;
    if (in->support < 0.25 * weight) x->landed = 0;
    out->landed = x->landed;
    out->idle = !in->armed || (x->landed && in->pos_ref[2] >= in->pos[2] - CTRL_LAND_MARGIN);
}
