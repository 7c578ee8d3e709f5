/*
 * The input clock of FMI 3.0 Scheduled Execution, which the FMI 3.0 glue (fmi3_glue.c) and
 * mdgen --scheduled-execution (tools/mdgen.c) must agree on.  No FMI type here: mdgen
 * includes it too.
 *
 * An FMU provides Scheduled Execution when its one translation unit defines
 * FP_FMI3_SCHEDULED_EXECUTION before anything else (fmu_src/CMakeLists.txt: add_fmu3 with
 * SCHEDULED_EXECUTION writes it into <Model>_all.c, so a build from sources/ has it too).
 * Its model then has one model partition: the model's step over one internal step (the fixed
 * Real scalar parameter FP_INTERNAL_STEP_NAMES names, fp_model.h: the controller's Ts), run
 * by fmi3ActivateModelPartition of one periodic input clock whose constant interval is that
 * parameter's default.  The clock is no table row: its value reference lies beyond the
 * table's (mdgen fails the build if an element of the FMI 2.0 numbering reaches it).
 */
#ifndef FP_FMI3_SCHEDULED_H
#define FP_FMI3_SCHEDULED_H

#define FP_SE_CLOCK_NAME "sample"
#define FP_SE_CLOCK_VR 5000u
/* the one input clock: priority 0 (mandatory for input clocks in Scheduled Execution) */
#define FP_SE_CLOCK_PRIORITY 0
#define FP_SE_CLOCK_DESCRIPTION                                                              \
    "Sample clock (Scheduled Execution): each activation at t0 + k Ts runs one sample from " \
    "the inputs set before it; the inputs and outputs belong to its model partition"

#endif
