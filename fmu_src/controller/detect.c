/*
 * Rotor-fault detection from the INDI residual, without being told.
 *
 * The residual is what the filtered measurements say the rotors deliver, minus what the
 * filtered actuator states give with the efficiencies in use: the body force
 * m R^T (acc - g e3) - f_b_m and the torque I dOmega + Omega x I Omega - tau_b_m.  H(s)
 * delays both sides alike, so in flight without fault or disturbance it stays near zero.
 * A rotor that loses the share delta of its efficiency leaves -delta w_i, w_i its own
 * wrench at full efficiency: a 6-D signature (force along its thrust axis, torque from its
 * arm and drag) that an external force or torque does not share.  Each sample fits the
 * residual with each rotor's signature alone (least squares, torques scaled by the mean arm
 * so newtons and newton-metres weigh alike); the rotor whose signature explains it best is
 * indicated when its loss exceeds loss_min and what it leaves unexplained is at most
 * fit_max of the residual.  Indicated for `persist` samples in a row, the rotor's efficiency
 * estimate drops to what the fit says; below 0.5 the rotor is lost and the controller
 * reconfigures exactly as when told (its single-failure force set).  Estimates only ever
 * fall: the next detection on the same rotor can lower it further, a reset restores it.
 */
#include <math.h>
#include <string.h>

#include "fp_math.h"
#include "stages.h"

void ctrl_detect_start(CtrlDetect *x) {
    int i;
    memset(x, 0, sizeof *x);
    for (i = 0; i < FP_MAX_ROTORS; i++) x->est[i] = 1.0;
    x->candidate = -1;
}

void ctrl_detect(const CtrlDetectParams *p, const FpRotorSet *rs, const CtrlFiltered *s,
                 CtrlDetect *x, CtrlDetectOut *out) {
    const double *r = s->r_m; /* R(mu_m), row-major */
    double fw[3], iw[3], wiw[3], res[6];
    double scale[6], rr = 0.0, best_u = INFINITY, best_d = 0.0;
    int i, j, best = -1;
    /* the body force the accelerometer says, and the torque the gyro says */
    for (i = 0; i < 3; i++) fw[i] = p->mass * (s->acc_m[i] - (i == 2 ? p->g : 0.0));
    m3_mul_v(&p->inertia[0][0], s->rate_m, iw);
    v3_cross(s->rate_m, iw, wiw);
    m3_mul_v(&p->inertia[0][0], s->ang_acc_m, iw);
    for (i = 0; i < 3; i++) {
        res[i] = r[i] * fw[0] + r[3 + i] * fw[1] + r[6 + i] * fw[2] - s->f_b_m[i];
        res[3 + i] = iw[i] + wiw[i] - s->tau_b_m[i];
        scale[i] = 1.0;
        /* arm^2 > 0: detect_params makes it so, and a restored state whose constants are
         * not detect_params' is refused (controller_check_restored) */
        scale[3 + i] = 1.0 / (p->arm * p->arm);
    }
    for (j = 0; j < 6; j++) rr += scale[j] * res[j] * res[j];
    for (i = 0; i < rs->n && i < FP_MAX_ROTORS; i++) {
        const double *w = s->w_rotor[i];
        double ww = 0.0, rw = 0.0, d, u;
        if (!(s->eff[i] > 0.0)) continue; /* lost already: nothing more to lose */
        for (j = 0; j < 6; j++) {
            ww += scale[j] * w[j] * w[j];
            rw += scale[j] * res[j] * w[j];
        }
        /* a rotor near standstill has no signature to fit: its loss would be noise */
        if (!(ww > p->wrench_min * p->wrench_min)) continue;
        d = -rw / ww;
        /* rr = 0 leaves rw = 0 unless the squares underflowed: then nothing to fit (0 / 0
         * made u NaN, never the best, before this test) */
        if (!(d > 0.0) || !(rr > 0.0)) continue;
        u = sqrt(fmax(rr - rw * rw / ww, 0.0) / rr);
        if (u < best_u) best_u = u, best_d = d, best = i;
    }
    memcpy(out->residual, res, sizeof out->residual);
    out->detected = -1;
    if (best >= 0 && best_d >= p->loss_min && best_u <= p->fit_max) {
        if (best == x->candidate)
            x->count++;
        else
            x->candidate = best, x->count = 1;
    } else {
        x->candidate = -1, x->count = 0;
    }
    if (best >= 0 && x->count >= p->persist) { /* (count >= persist >= 1 has best >= 0) */
        x->est[best] = fmin(x->est[best], fmax(s->eff[best] - best_d, 0.0));
        x->found_mask |= (int32_t)1 << best;
        x->candidate = -1, x->count = 0;
        out->detected = best;
    }
}
