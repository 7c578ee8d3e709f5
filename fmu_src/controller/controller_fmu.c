/* Binds the controller model to the generic FMI layer of the FullPoseController FMU. */
#include "controller.h"

const FpModelInfo *fp_model_info(void) { return controller_model_info(); }
