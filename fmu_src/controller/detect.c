/*
 * Rotor-fault detection without being told: a lost or weakened rotor told apart from an
 * unknown load (mass or payload mismatch, wind, a push) by how the residual follows the
 * rotor's own wrench over time.
 *
 * The residual is what the raw measurements say the rotors deliver minus what the raw
 * actuator measurements give with the efficiencies in use:
 *     r = [m R^T (acc - g e3);  I dOmega + Omega x I Omega] - sum_i e_i w_i,
 * w_i the wrench of rotor i at full efficiency, dOmega the body rates' difference over the
 * sample (both sides taken at the sample's midpoint).  Raw and not H(s)-filtered, so that a
 * change of the plant shows in r with its own time profile and no filter transient.  Both
 * sides are mapped to the accelerations they cause (forces over m, torques through arm I^-1),
 * so each channel weighs as its sensor measures it and the yaw channel, a differentiated gyro
 * with the largest inertia, does not drown the others in noise.
 *
 * While nothing happens, r sits at a quiet level (a constant load, a mass mismatch: zero
 * when the model is right) that r follows slowly.  A change of r beyond `onset` opens an
 * event, and from then on two explanations of the change dr = r - level are fitted by least
 * squares over the event's samples:
 *   - a load: dr = d, constant (6 parameters);
 *   - rotor i's efficiency changed by -delta: dr = -delta w_i(t) (1 parameter).
 * The controller answers every change by moving its actuators, and with them w_i(t): a
 * rotor's fault then follows w_i as it moves, while a load stays put.  A rotor is concluded
 * when its fit leaves at most fit_max of dr unexplained and the load's fit leaves at least 4
 * times as much (plus a noise floor): the excitation the allocation gives tells them apart.
 * Its estimate becomes e_i - delta (either way: estimates rise again when a rotor turns out
 * better than assumed); below CTRL_DETECT_LOST the rotor is lost (the controller
 * reconfigures and idles its motor at a probe speed, so that a rotor that does produce
 * thrust shows it and is restored at CTRL_DETECT_RESTORE).  An event no rotor explains
 * within `window` samples is a load: the quiet level takes it in.
 */
#include <math.h>
#include <string.h>

#include "fp_math.h"
#include "stages.h"

/* Per sample: the share of the residual change the onset detector's average takes in. */
#define ONSET_GAIN 0.1
/* The onset average's noise is the per-sample noise times sqrt(g / (2 - g)); an event opens
 * at ONSET_SIGMAS of it (or p->onset, when larger). */
#define ONSET_SIGMAS 4.0
/* How much worse the load's fit must be than the rotor's to conclude a fault (a ratio), and
 * by how many samples' worth of noise at least (a significance: the load has 5 parameters
 * more, and fits that many samples' noise better by chance). */
#define LOAD_RATIO 2.0
#define GAP_NOISE 20.0

void ctrl_detect_start(CtrlDetect *x) {
    int i;
    memset(x, 0, sizeof *x);
    for (i = 0; i < FP_MAX_ROTORS; i++) x->est[i] = 1.0;
}

void ctrl_detect_residual(const CtrlDetectParams *p, const CtrlFiltered *s, double res[6]) {
    const double *r = s->r_m; /* R(mu_m), row-major */
    double fw[3], iw[3], wiw[3];
    int i;
    for (i = 0; i < 3; i++) fw[i] = p->mass * (s->acc_m[i] - (i == 2 ? p->g : 0.0));
    m3_mul_v(&p->inertia[0][0], s->rate_m, iw);
    v3_cross(s->rate_m, iw, wiw);
    m3_mul_v(&p->inertia[0][0], s->ang_acc_m, iw);
    for (i = 0; i < 3; i++) {
        res[i] = r[i] * fw[0] + r[3 + i] * fw[1] + r[6 + i] * fw[2] - s->f_b_m[i];
        res[3 + i] = iw[i] + wiw[i] - s->tau_b_m[i];
    }
}

/* A torque as the angular acceleration it causes, times the mean arm. */
static void torque_to_acc(const CtrlDetectParams *p, const double tau[3], double a[3]) {
    m3_mul_v(&p->acc_of_torque[0][0], tau, a);
}

static double dot6(const double *a, const double *b) {
    double s = 0.0;
    int j;
    for (j = 0; j < 6; j++) s += a[j] * b[j];
    return s;
}

/* This sample's raw signals into the ring: the body force per unit mass the accelerometer
 * says, the body rates, each rotor's wrench at full efficiency as accelerations. */
static void push(const CtrlDetectParams *p, const FpRotorSet *rs, const FpRotorTrig *mounts,
                 const CtrlDetectInputs *in, int n, CtrlDetect *x) {
    FpRotorTrig tr;
    double r[9], a[3];
    int i, k = x->head;
    rot_zyx_jacobian(in->euler, r, NULL, NULL);
    for (i = 0; i < 3; i++) a[i] = in->acc[i] - (i == 2 ? p->g : 0.0);
    for (i = 0; i < 3; i++) {
        x->force[k][i] = r[i] * a[0] + r[3 + i] * a[1] + r[6 + i] * a[2];
        x->rate[k][i] = in->rate[i];
    }
    memcpy(tr.sg, mounts->sg, sizeof tr.sg);
    memcpy(tr.cg, mounts->cg, sizeof tr.cg);
    fp_rotor_trig_tilts(rs, in->alpha, in->beta, &tr);
    for (i = 0; i < n; i++) {
        double w[6];
        int j;
        fp_rotor_wrench_one(rs, &tr, i, in->omega[i], w);
        for (j = 0; j < 3; j++) x->wrench[k][i][j] = w[j] / p->mass;
        torque_to_acc(p, w + 3, &x->wrench[k][i][3]);
    }
    x->head = (k + 1) % (CTRL_DETECT_SPAN + 1);
    if (x->filled <= CTRL_DETECT_SPAN) x->filled++;
}

/* The measured wrench y and each rotor's w over the ring's span, as accelerations: the mean
 * of the span's midpoints (trapezoid weights), the angular acceleration from the rates at
 * its ends.  Averaging a few samples takes the differentiated gyro's noise down by the
 * span; a change shows in full once the span has passed it. */
static void averaged(const CtrlDetectParams *p, const CtrlDetect *x, int n, double y[6],
                     double w[][6]) {
    const int span = CTRL_DETECT_SPAN, oldest = x->head, newest = (x->head + span) % (span + 1);
    double rate[3] = {0.0, 0.0, 0.0}, dw[3], iw[3], wiw[3], tau[3];
    int i, j, k;
    memset(y, 0, 6 * sizeof y[0]);
    for (i = 0; i < n; i++) memset(w[i], 0, 6 * sizeof w[i][0]);
    for (k = 0; k <= span; k++) {
        int slot = (oldest + k) % (span + 1);
        double c = (k == 0 || k == span ? 0.5 : 1.0) / span;
        for (j = 0; j < 3; j++) y[j] += c * x->force[slot][j], rate[j] += c * x->rate[slot][j];
        for (i = 0; i < n; i++)
            for (j = 0; j < 6; j++) w[i][j] += c * x->wrench[slot][i][j];
    }
    for (j = 0; j < 3; j++) dw[j] = (x->rate[newest][j] - x->rate[oldest][j]) / (span * p->Ts);
    m3_mul_v(&p->inertia[0][0], rate, iw);
    v3_cross(rate, iw, wiw);
    m3_mul_v(&p->inertia[0][0], dw, iw);
    for (j = 0; j < 3; j++) tau[j] = iw[j] + wiw[j];
    torque_to_acc(p, tau, y + 3);
}

/* Conclude the open event: rotor `best` at efficiency e_new, or (best < 0) a load, which
 * the quiet level takes in (and its scatter, the noise). */
static void conclude(CtrlDetect *x, int best, double e_new, CtrlDetectOut *out) {
    int i;
    if (best >= 0) {
        int32_t bit = (int32_t)1 << best;
        x->est[best] = e_new;
        x->found_mask |= bit;
        if (e_new < CTRL_DETECT_LOST) x->lost_mask |= bit;
        if (e_new >= CTRL_DETECT_RESTORE) x->lost_mask &= ~bit;
        out->detected = best;
    } else if (x->n > 0) {
        for (i = 0; i < 6; i++) x->base[i] += x->s_r[i] / x->n;
        x->noise2 = fmax(x->noise2, (x->s_rr - dot6(x->s_r, x->s_r) / x->n) / x->n);
    }
    x->active = 0;
    memset(x->onset, 0, sizeof x->onset);
}

void ctrl_detect(const CtrlDetectParams *p, const FpRotorSet *rs, const FpRotorTrig *mounts,
                 const CtrlDetectInputs *in, CtrlDetect *x, CtrlDetectOut *out) {
    double y[6], w[FP_MAX_ROTORS][6], d[6], on2 = 0.0, dd, noise2, on_min2;
    int i, j, n = rs->n < FP_MAX_ROTORS ? rs->n : FP_MAX_ROTORS;
    out->detected = -1;
    push(p, rs, mounts, in, n, x);
    if (x->filled <= CTRL_DETECT_SPAN) return; /* the span is not full yet */
    averaged(p, x, n, y, w);
    for (j = 0; j < 6; j++) {
        double r = y[j];
        for (i = 0; i < n; i++) r -= in->eff[i] * w[i][j];
        d[j] = r - x->base[j];
        x->onset[j] += ONSET_GAIN * (d[j] - x->onset[j]);
        on2 += x->onset[j] * x->onset[j];
    }
    dd = dot6(d, d);
    /* the residual's noise per sample, measured (at least the floor) */
    noise2 = fmax(x->noise2, p->floor2);
    on_min2 = fmax(p->onset * p->onset,
                   ONSET_SIGMAS * ONSET_SIGMAS * noise2 * ONSET_GAIN / (2.0 - ONSET_GAIN));
    if (!x->active) {
        if (on2 < on_min2) { /* quiet: the level and the noise follow */
            for (j = 0; j < 6; j++) x->base[j] += p->base_gain * d[j];
            x->noise2 += p->base_gain * (dd - x->noise2);
            return;
        }
        /* an event: its sums start once the span has passed the change, so that every
         * sample summed shows it in full */
        x->active = 1, x->n = 1 - CTRL_DETECT_SPAN, x->s_rr = 0.0;
        memset(x->s_r, 0, sizeof x->s_r);
        memset(x->s_ww, 0, sizeof x->s_ww);
        memset(x->s_wr, 0, sizeof x->s_wr);
    }
    if (x->n < 0) {
        x->n++;
        return;
    }
    x->n++;
    x->s_rr += dd;
    for (j = 0; j < 6; j++) x->s_r[j] += d[j];
    for (i = 0; i < n; i++) {
        x->s_ww[i] += dot6(w[i], w[i]);
        x->s_wr[i] += dot6(w[i], d);
    }
    if (x->n >= p->persist && x->s_rr > 0.0) {
        /* what each explanation leaves beyond the noise measured (n samples of it; the
         * floor enters the significance below, not this share) */
        double noise = x->n * x->noise2, signal = fmax(x->s_rr - noise, 0.0);
        double sse_load = fmax(x->s_rr - dot6(x->s_r, x->s_r) / x->n - noise, 0.0);
        double best_sse = INFINITY, best_e = 1.0;
        int best = -1;
        for (i = 0; i < n; i++) {
            double delta, e_new, sse;
            /* a rotor near standstill over the event has no signature to fit */
            if (!(x->s_ww[i] > x->n * p->wrench_min * p->wrench_min)) continue;
            delta = -x->s_wr[i] / x->s_ww[i];
            e_new = fp_clamp(in->eff[i] - delta, 0.0, 1.0);
            if (!(fabs(e_new - in->eff[i]) >= p->loss_min)) continue;
            sse = fmax(x->s_rr - x->s_wr[i] * x->s_wr[i] / x->s_ww[i] - noise, 0.0);
            if (sse < best_sse) best_sse = sse, best = i, best_e = e_new;
        }
        if (best >= 0 && signal > noise && best_sse <= p->fit_max * p->fit_max * signal &&
            sse_load >= LOAD_RATIO * best_sse && sse_load - best_sse >= GAP_NOISE * noise2) {
            conclude(x, best, best_e, out);
            return;
        }
    }
    if (x->n >= p->window) conclude(x, -1, 1.0, out);
}
