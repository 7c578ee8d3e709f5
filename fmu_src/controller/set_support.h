/*
 * Internal to the derivation of the feasible-force sets (derive_sets.c, set_support.c): the
 * support function of a set of rotors, and what the two files share.  Not part of the
 * controller's API (derive_sets.h has the method).  Calls go one way: derive_sets.c calls
 * set_support.c.
 */
#ifndef CTRL_SET_SUPPORT_H
#define CTRL_SET_SUPPORT_H

#include <stdio.h>

#include "derive_sets.h"


#define SET_REL_TOL 1e-9   /* geometric tolerances, times the force scale */

static inline void set_why(char *why, int size, const char *text) {
    if (why && size > 0) snprintf(why, (size_t)size, "%s", text);
}

/* The LP of the rotors loaded into w (inner model, torque rows), started feasible:
 * CTRL_SET_EMPTY when zero torque is out of reach. */
CtrlSetStatus ctrl_set_lp_start(CtrlSetWork *w, char *why, int why_size);

/* Support along unit c: the inner point p (an attainable force) and the outer offset h. */
CtrlSetStatus ctrl_set_support(CtrlSetWork *w, const double c[3], double p[3], double *h,
                               char *why, int why_size);

#endif
