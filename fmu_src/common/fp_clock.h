/* Monotonic clock for optional self-timing (benchmarks, the paper's Fig. 8). */
#ifndef FP_CLOCK_H
#define FP_CLOCK_H

/* Seconds on a monotonic clock; 0 where none is available. */
double fp_clock_seconds(void);

#endif
