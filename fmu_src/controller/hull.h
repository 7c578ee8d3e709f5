/*
 * The incremental 3-D convex hull (hull.c) the derivation of the force sets builds its inner
 * and outer polytopes with (derive_sets.c): points given by index into an array of the
 * caller's, faces in a CtrlHull (derive_sets.h, with the working memory that holds them).
 */
#ifndef CTRL_HULL_H
#define CTRL_HULL_H

#include "derive_sets.h"

/* The distance of x from the line through a along the unit vector u. */
double ctrl_dist_line(const double a[3], const double u[3], const double x[3]);

/* Adds point k of p to the hull h: 1 added, 0 inside (within eps), -1 face cap exceeded. */
int ctrl_hull_add(CtrlHull *h, const double (*p)[3], int k, double eps);

/* The hull of points 0..n-1: 1, or 0 when they span less than 3-D (within eps), -1 caps. */
int ctrl_hull_build(CtrlHull *h, const double (*p)[3], int n, double eps);

#endif
