# THE source lists of the models, shared by the FMUs' build (CMakeLists.txt) and the embedded
# build of the controller (embedded/CMakeLists.txt): what a board compiles is what the FMU is
# compiled from.
set(FP_COMMON_SOURCES common/fp_model.c common/fp_clock.c common/fp_params.c common/fp_table.c)
set(FP_COMMON_HEADERS common/fp_model.h common/fp_clock.h common/fp_params.h common/fp_math.h
  common/fmu_state.h common/fp_table.h)
set(FP_MULTIROTOR_SOURCES common/multirotor.c)
set(FP_MULTIROTOR_HEADERS common/multirotor.h common/airframe_vars.h)
set(FP_WLS_SOURCES common/wls.c common/wls_active_set.c common/wls_qr.c common/wls_phase1.c
  common/wls_scale.c)
set(FP_WLS_HEADERS common/wls.h common/wls_internal.h)
set(FP_PLANT_SOURCES plant/plant.c plant/contact.c)
# the scenario's signals played from a table (the SSP export's third component)
set(FP_SIGNALS_SOURCES signals/signals.c)
set(FP_SIGNALS_HEADERS signals/signals.h signals/signals_vars.h)
set(FP_PLANT_HEADERS plant/plant.h plant/plant_vars.h plant/contact.h)
# the controller's derivation of its force sets, also in the host API (fp_controller below)
set(FP_DERIVE_SETS_SOURCES controller/derive_sets.c controller/set_support.c controller/hull.c)
set(FP_CONTROLLER_SOURCES
  controller/controller.c
  controller/controller_sample.c
  controller/validate.c
  controller/filters.c
  controller/force_sets.c
  ${FP_DERIVE_SETS_SOURCES}
  controller/guidance.c
  controller/reference.c
  controller/detect.c
  controller/shaping_limits.c
  controller/derive_params.c
  controller/stabilization.c
  controller/allocation.c
  controller/ground.c)
set(FP_CONTROLLER_HEADERS
  controller/controller.h
  controller/controller_vars.h
  controller/derive_sets.h
  controller/set_support.h
  controller/hull.h
  controller/stages.h
  controller/default_gains.h
)
