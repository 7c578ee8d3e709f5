/* Binds the signal player to the generic FMI layer of the ScenarioSignals FMU. */
#include "signals.h"

const FpModelInfo *fp_model_info(void) { return signals_model_info(); }
