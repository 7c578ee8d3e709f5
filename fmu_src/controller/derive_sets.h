/*
 * The feasible-force sets of an airframe, derived from its rotors alone (paper eq. 5-6):
 *
 *     S(0) = { sum_i f_i : f_i in conv U_i, sum_i M_i f_i = 0 }
 *
 * with U_i = { T t_i(alpha, beta) : T in [k_t omega_min^2, k_t omega_max^2], (alpha, beta)
 * in rotor i's servo box } and M_i f_i the torque of rotor i's force (eq. 3).  The controller
 * derives S(0) and the set after losing each rotor at initialization from its airframe
 * parameters, so an importer that sets only the airframe gets a controller for that vehicle;
 * the Python design tool (controller/force_sets.py, scipy) computes the same sets as its
 * oracle.  Method (docs/controller.md, "Force sets from the airframe"):
 *
 *  - Support function h(c) = max c.f over the set by a revised simplex on the inner model
 *    (each U_i sampled on a CTRL_SET_GRID x CTRL_SET_GRID lattice of servo angles at both
 *    thrust limits, or the origin when omega_min = 0); its maximiser is an attainable force
 *    (an inner point).  The LP's torque multipliers y give, by weak duality, an offset valid
 *    for the continuous servo box: h(c) <= sum_i max_{f in conv U_i} (c - M_i^T y).f, each
 *    term in closed form (the maximum of the thrust direction's projection over a box of
 *    two angles is two one-dimensional cosine maxima).  The facet {c.f <= that} therefore
 *    contains every force of real actuator states.
 *  - Directions: seeded with the 6 axes and 8 cube diagonals; a full-dimensional set is
 *    refined by the sandwich rule: the facet of the inner hull beyond which the outer
 *    polytope sticks out most (relative to the force magnitude) gives the next direction,
 *    until the cap of non-redundant facets, or until the two agree.  Lower-dimensional sets
 *    (vertical rotors: a segment) are written with pairs of opposite facets across their
 *    affine hull.
 *
 * Everything lives in a caller-provided CtrlSetWork (no heap, no globals): the controller
 * keeps it on its initialization stack frame.
 */
#ifndef CTRL_DERIVE_SETS_H
#define CTRL_DERIVE_SETS_H

#include <stdint.h>

#include "fp_model.h"
#include "multirotor.h"

#ifndef CTRL_SET_GRID
#define CTRL_SET_GRID 9 /* servo-angle samples per axis of the inner model */
#endif
#define CTRL_SET_DIRS (CTRL_SET_GRID * CTRL_SET_GRID)
#define CTRL_SET_MAX_DIRS 128      /* support directions evaluated per set */
#define CTRL_SET_MAX_POINTS CTRL_SET_MAX_DIRS
#define CTRL_SET_MAX_FACES (2 * CTRL_SET_MAX_POINTS)
#define CTRL_LP_MAX_ROWS (3 + FP_MAX_ROTORS)

/* A triangle of a 3-D convex hull: vertex indices (counter-clockwise seen from outside),
 * outward unit normal and offset. */
typedef struct {
    int32_t v[3];
    double n[3], off;
} CtrlHullFace;

typedef struct {
    int32_t n_faces;
    double interior[3];
    CtrlHullFace f[CTRL_SET_MAX_FACES];
} CtrlHull;

/* The working memory of a derivation (about 60 kB). */
typedef struct {
    /* the rotors of the set being built */
    int32_t n;                       /* rotors in the set */
    int32_t slot[FP_MAX_ROTORS];     /* their airframe slots */
    int32_t n_dirs[FP_MAX_ROTORS];   /* inner-model thrust directions per rotor */
    double dir[FP_MAX_ROTORS][CTRL_SET_DIRS][3];
    double M[FP_MAX_ROTORS][3][3];   /* torque per unit body force of the rotor */
    double gamma[FP_MAX_ROTORS], box[FP_MAX_ROTORS][4]; /* alpha_min/max, beta_min/max */
    double t_min, t_max, scale;      /* thrust limits (N); force scale sum T_max */
    /* the LP: rows 0-2 torque, 3 + r convexity of rotor r; column ids col_id() */
    int32_t m;
    int32_t basis[CTRL_LP_MAX_ROWS];
    double binv[CTRL_LP_MAX_ROWS][CTRL_LP_MAX_ROWS];
    double xb[CTRL_LP_MAX_ROWS];
    int32_t pivots;                  /* since the last refactorisation */
    int64_t lp_solves, lp_pivots;    /* totals, for the benchmark */
    /* the directions evaluated, their outer offsets and the inner points */
    int32_t n_c, n_p;
    double c[CTRL_SET_MAX_DIRS][3], b[CTRL_SET_MAX_DIRS];
    double p[CTRL_SET_MAX_POINTS][3];
    double q[CTRL_SET_MAX_DIRS][3];  /* dual points of the outer facets */
    CtrlHull inner, outer;
    int32_t used[CTRL_SET_MAX_DIRS]; /* outer facet j is a vertex of the dual hull */
} CtrlSetWork;

typedef enum {
    CTRL_SET_OK = 0,
    CTRL_SET_EMPTY = 1, /* no combination of actuator states produces zero torque */
    CTRL_SET_FAILED = 2 /* a cap or the LP's iteration limit was hit (see why) */
} CtrlSetStatus;

/*
 * S(0) of the rotors of rs not in lost_mask (bit i: slot i), as at most `cap` facets
 * {A f <= b} with unit normals (cap >= 8); *n_out facets written, *dim the set's dimension
 * (0..3).  CTRL_SET_EMPTY: no force at zero torque at all (n_out 0).
 */
CtrlSetStatus ctrl_derive_force_set(const FpRotorSet *rs, int32_t lost_mask, int cap,
                                    CtrlSetWork *w, double A[][3], double b[], int32_t *n_out,
                                    int32_t *dim, char *why, int why_size);

/* The support h(c) = max c.f of {A f <= b} (n facets) and an interior-side test helper:
 * the largest c.f over the polytope's vertices, computed with the dual hull about the
 * interior point o (strictly inside).  FP_ERROR when the polytope is unbounded or o is not
 * inside. */
FpStatus ctrl_polytope_max(const double A[][3], const double b[], int n, const double o[3],
                           const double c[][3], int n_c, CtrlSetWork *w, double h[]);

#endif
