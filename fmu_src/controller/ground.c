/*
 * The controller on the ground (stage "ground", before the cascade): what the ground
 * carries of the vehicle, whether it has landed, and whether the rotors idle.
 *
 * The ground's support is what the measured acceleration leaves unexplained by the rotors
 * and gravity: m a = R f_b + m g e_z + F_ground, so its upward part is
 * m g + (R f_b)_z - m a_z (NED).  In flight it is the vertical disturbance (zero without
 * one); resting on the gear with the rotors stopped it is the weight.  The vehicle has landed
 * once the ground carries half its weight or more while it is at rest (speed below
 * CTRL_LAND_SPEED) for CTRL_LAND_TIME, and has left the ground when the support falls under
 * a quarter of the weight.  The rotors idle when the vehicle is disarmed, or landed with the
 * reference not above it (no higher than CTRL_LAND_MARGIN above the measured position): a
 * landing ends with the rotors stopped, and a reference above starts a takeoff.
 */
#include <math.h>

#include "controller.h"
#include "fp_math.h"
#include "stages.h"

void ctrl_ground(const CtrlGroundParams *p, const CtrlGroundInputs *in, CtrlGroundState *x,
                 CtrlGroundOut *out) {
    double r[3][3], fw[3], weight = p->mass * fabs(p->g), speed;
    double e[3];
    int i, need = (int)ceil(CTRL_LAND_TIME / p->Ts - 1e-9);
    for (i = 0; i < 3; i++) e[i] = in->euler[i];
    {
        double rx[3][3], ry[3][3], rz[3][3], t[3][3];
        rot_x(e[0], rx);
        rot_y(e[1], ry);
        rot_z(e[2], rz);
        m3_mul(&rz[0][0], &ry[0][0], &t[0][0]);
        m3_mul(&t[0][0], &rx[0][0], &r[0][0]);
    }
    m3_mul_v(&r[0][0], in->f_b, fw);
    out->support = weight + fw[2] - p->mass * in->acc[2];
    speed = sqrt(in->vel[0] * in->vel[0] + in->vel[1] * in->vel[1] + in->vel[2] * in->vel[2]);
    if (out->support >= 0.5 * weight && speed < CTRL_LAND_SPEED) {
        if (x->carried < need) x->carried++;
    } else {
        x->carried = 0;
    }
    if (x->carried >= need) x->landed = 1;
    if (out->support < 0.25 * weight) x->landed = 0;
    out->landed = x->landed;
    out->idle = !in->armed || (x->landed && in->pos_ref[2] >= in->pos[2] - CTRL_LAND_MARGIN);
}
