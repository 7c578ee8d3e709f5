/* Binds the plant model to the generic FMI layer of the MultirotorPlant FMU. */
#include "plant.h"

const FpModelInfo *fp_model_info(void) { return plant_model_info(); }
