/* ScenarioSignals: plays a table of reference and disturbance signals from its resources/
 * (common/fp_table.h) on the outputs named like the inputs they feed (signals_vars.h). */
#ifndef SIGNALS_H
#define SIGNALS_H

#include <stdint.h>

#include "fp_model.h"

#define SIGNALS_RESOURCE "signals.fptable"
#define SIGNALS_N_OUTPUTS 40 /* Real output elements */

typedef struct {
    /* outputs */
    double pos_ref[3], euler_ref[3], vel_ref[3], acc_ref[3], euler_rate_ref[3];
    double rotor_health[8];
    double f_d[3], tau_d[3], a_d[3];
    double efficiency[8];
    int32_t row;
    int32_t initialized; /* the glue's marker (FpModelInfo.initialized_offset) */
    /* derived at initialization: the table column of each Real output element (-1: none),
     * in table order of the elements */
    int32_t column[SIGNALS_N_OUTPUTS];
} SignalsModel;

/* The model; its FMU returns it from fp_model_info(). */
const FpModelInfo *signals_model_info(void);

#endif
