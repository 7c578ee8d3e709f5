/*
 * The contract between a model and the generic FMI layer.
 *
 * A model is a plain C struct (no pointers, so the FMI layer can snapshot it
 * with memcpy), one variable table describing which struct members are FMU
 * variables, and a handful of callbacks.  Nothing here mentions FMI types:
 * the same model can sit behind the FMI 2.0 glue, the Python core library or
 * a future FMI 3.0 layer.
 */
#ifndef FP_MODEL_H
#define FP_MODEL_H

#include <stddef.h>
#include <stdint.h>

/* Compile-time assertion that works in C99. */
#define FP_STATIC_ASSERT(cond, tag) typedef char fp_static_assert_##tag[(cond) ? 1 : -1]

typedef enum { FP_OK = 0, FP_WARNING = 1, FP_DISCARD = 2, FP_ERROR = 3 } FpStatus;

typedef enum { FP_REAL = 0, FP_INTEGER = 1, FP_BOOLEAN = 2 } FpVarType;

/* Causality + variability in one: the combinations our FMUs use. */
typedef enum {
    FP_PARAM_FIXED = 0,   /* parameter, fixed: set before initialization only */
    FP_PARAM_TUNABLE = 1, /* parameter, tunable: may change between steps */
    FP_INPUT = 2,         /* input, continuous (Real) or discrete (Integer/Boolean) */
    FP_OUTPUT = 3,        /* output, calculated */
    /* Model Exchange (FpModelExchange): a Real row of continuous states, local and
     * continuous, calculated; never set by value (fmi2SetContinuousStates sets states) */
    FP_STATE = 4,
    /* the derivative of a state row, local and continuous, calculated: the row named "der_"
     * followed by the state row's name, of the same shape (tools/mdgen.c checks it) */
    FP_DERIVATIVE = 5,
    /* a Real the model computes for an importer to read, local and continuous, calculated
     * (the plant's contact depths: its event indicators, FpModelExchange.indicators) */
    FP_LOCAL = 6
} FpVarKind;

/*
 * Declared types: the physical kind of a Real variable, written to modelDescription.xml as a
 * <SimpleType> with its quantity, unit and (where the magnitude is far from 1) nominal; a
 * variable names its kind in its table row and inherits all three.
 * T(id, name, quantity, unit, nominal); nominal 0: none (FMI's default, 1).
 */
#define FP_DECLARED_TYPES(T)                                                                 \
    T(NONE, "", "", "", 0.0) /* Integer and Boolean variables */                           \
    T(TIME, "Time", "Time", "s", 0.0)                                                       \
    T(MASS, "Mass", "Mass", "kg", 0.0)                                                      \
    T(INERTIA, "MomentOfInertia", "MomentOfInertia", "kg.m2", 1e-2)                         \
    T(LENGTH, "Length", "Length", "m", 0.0)                                                 \
    T(VELOCITY, "Velocity", "Velocity", "m/s", 0.0)                                         \
    T(ACCELERATION, "Acceleration", "Acceleration", "m/s2", 0.0)                            \
    T(JERK, "Jerk", "Jerk", "m/s3", 0.0)                                                    \
    T(ANGLE, "Angle", "Angle", "rad", 0.0)                                                  \
    T(ANGULAR_VELOCITY, "AngularVelocity", "AngularVelocity", "rad/s", 0.0)                 \
    T(ANGULAR_ACCELERATION, "AngularAcceleration", "AngularAcceleration", "rad/s2", 0.0)    \
    T(ANGULAR_FREQUENCY, "AngularFrequency", "AngularFrequency", "rad/s", 0.0)              \
    T(ROTOR_SPEED, "RotorSpeed", "AngularVelocity", "rad/s", 1e2)                           \
    T(FORCE, "Force", "Force", "N", 0.0)                                                    \
    T(TORQUE, "Torque", "Torque", "N.m", 0.0)                                               \
    T(STIFFNESS, "TranslationalSpringConstant", "TranslationalSpringConstant", "N/m", 1e3)  \
    T(DAMPING, "TranslationalDampingConstant", "TranslationalDampingConstant", "N.s/m", 0.0) \
    T(THRUST_COEFFICIENT, "ThrustCoefficient", "ThrustCoefficient", "N.s2/rad2", 1e-4)      \
    T(DRAG_COEFFICIENT, "DragTorqueCoefficient", "DragTorqueCoefficient", "N.m.s2/rad2",    \
      1e-6)                                                                                 \
    T(RATIO, "Ratio", "Ratio", "1", 0.0) /* efficiencies, health, margins, damping */       \
    T(WEIGHT, "Weight", "Weight", "1", 0.0) /* QP weights */                                \
    T(DIMENSIONLESS, "Dimensionless", "Dimensionless", "1", 0.0) /* normals, quaternion */  \
    T(BLOCK_GAIN, "BlockGain", "InverseTime", "1/s", 0.0) /* C, D of the control blocks */ \
    /* a 6-vector [force (N); torque (N.m)]: elements 1-3 are FORCE, 4-6 TORQUE */          \
    T(WRENCH, "", "", "", 0.0)                                                              \
    /* the rate of a dimensionless quantity (the plant's quaternion derivative) */           \
    T(DIMENSIONLESS_RATE, "DimensionlessRate", "InverseTime", "1/s", 0.0)

#define FP_TYPE_ENUM(id, name, quantity, unit, nominal) FP_T_##id,
typedef enum { FP_DECLARED_TYPES(FP_TYPE_ENUM) FP_N_TYPES } FpTypeId;
#undef FP_TYPE_ENUM

typedef struct {
    const char *name; /* the SimpleType's name, "" for none */
    const char *quantity;
    const char *unit; /* "" for none */
    double nominal;   /* 0: none */
} FpDeclaredType;

const FpDeclaredType *fp_declared_type(FpTypeId id);

/*
 * The range a variable's value must lie in.  It is both the min/max that modelDescription.xml
 * declares and the bound the model's own checks read (fp_params.h), so the two cannot
 * differ.  FMI's min and max are inclusive, so tools/mdgen.c declares an open bound at the
 * nearest double inside it, the first value the check accepts (mass > 0: the smallest
 * positive double, min="4.9406564584124654e-324"; K_pos_A in (-1, 1):
 * max="0.99999999999999989"): the declared [min, max] holds exactly the values
 * fp_range_contains accepts, and the description ends with the interval as the check states
 * it ("; range (0, inf)").
 */
typedef struct {
    double lo, hi;
    unsigned flags; /* FP_RANGE_* */
} FpRange;

#define FP_RANGE_LO 1u      /* lo is a bound */
#define FP_RANGE_HI 2u      /* hi is a bound */
#define FP_RANGE_LO_OPEN 4u /* v > lo, not v >= lo */
#define FP_RANGE_HI_OPEN 8u /* v < hi, not v <= hi */

/* The ranges a table row may give (in the row's range column). */
#define FP_ANY {0.0, 0.0, 0u}
#define FP_POSITIVE {0.0, 0.0, FP_RANGE_LO | FP_RANGE_LO_OPEN}                /* (0, inf) */
#define FP_NONNEGATIVE {0.0, 0.0, FP_RANGE_LO}                                /* [0, inf) */
#define FP_IN(a, b) {(a), (b), FP_RANGE_LO | FP_RANGE_HI}                     /* [a, b] */
#define FP_IN_OPEN(a, b) \
    {(a), (b), FP_RANGE_LO | FP_RANGE_HI | FP_RANGE_LO_OPEN | FP_RANGE_HI_OPEN} /* (a, b) */
#define FP_IN_LOPEN(a, b) {(a), (b), FP_RANGE_LO | FP_RANGE_HI | FP_RANGE_LO_OPEN} /* (a, b] */

/* The knowns list of a table's InitialUnknowns declaration (e.g. PLANT_INITIAL_DEPENDENCIES in
 * plant/plant_vars.h) may name this for every parameter of the model. */
#define FP_ALL_PARAMETERS "@parameters "

/* 1 if v lies in r (NaN lies in no bounded range).  Inline: the controller checks every
 * input against its range every sample. */
static inline int fp_range_contains(const FpRange *r, double v) {
    if (r->flags & FP_RANGE_LO) {
        if ((r->flags & FP_RANGE_LO_OPEN) ? !(v > r->lo) : !(v >= r->lo)) return 0;
    }
    if (r->flags & FP_RANGE_HI) {
        if ((r->flags & FP_RANGE_HI_OPEN) ? !(v < r->hi) : !(v <= r->hi)) return 0;
    }
    return 1;
}

/* r as an interval, "[0, 1]", "(0, inf)", "1..8" (integer), with multiples of pi/4 written
 * as such ("[-pi/2, pi/2]"). */
const char *fp_range_text(const FpRange *r, int integer, char *buf, size_t size);

/*
 * One row of a model's variable table.  An entry may be a scalar
 * (rows = cols = 1), a vector (cols = 1, names "x[1]".."x[rows]") or a
 * row-major matrix ("x[i,j]").  Element k has value reference vr + k.
 * Real members are double, Integer members int32_t, Boolean members int32_t
 * holding 0 or 1.
 */
typedef struct {
    const char *name;
    uint32_t vr;
    FpVarType type;
    FpVarKind kind;
    uint16_t rows, cols;
    size_t offset;
    FpTypeId dtype; /* declared type (unit, quantity, nominal); FP_T_NONE if not Real */
    FpRange range;  /* min/max of every element, checked by the model */
    const char *description;
} FpVar;

/* The declared type of element k of v (a WRENCH row is FORCE then TORQUE). */
FpTypeId fp_var_element_type(const FpVar *v, uint32_t k);

/* The row called name in a table, or NULL. */
const FpVar *fp_var_find(const FpVar *vars, size_t n_vars, const char *name);

/* Log categories, shared by every model (names appear in modelDescription.xml). */
typedef enum {
    FP_LOG_EVENTS = 0,  /* lifecycle: instantiation, initialization, reset */
    FP_LOG_WARNING = 1, /* status warnings */
    FP_LOG_ERROR = 2,   /* status errors */
    FP_LOG_CALLS = 3,   /* every FMI call (very verbose) */
    FP_LOG_MODEL = 4,   /* model-specific diagnostics */
    FP_LOG_N_CATEGORIES = 5
} FpLogCategory;

const char *fp_log_category_name(int category);
const char *fp_log_category_description(int category);

struct FpTable;

/* A model logs through this; the FMI layer maps it to the importer's callback.  It also
 * carries the one thing a model reads from outside its struct: the table the glue loaded
 * from the FMU's resources/ (FpModelInfo.table_resource, common/fp_table.h), NULL for a model
 * without one. */
typedef struct {
    void (*log)(void *env, FpStatus status, FpLogCategory category, const char *message);
    void *env;
    const struct FpTable *table;
} FpLogger;

/* A real number as a message shows it: the shortest of %.15g, %.16g, %.17g that reads back
 * as the same double ("-0.8", not "-0.80000000000000004").  buf holds FP_REAL_TEXT chars. */
#define FP_REAL_TEXT 32
const char *fp_real_text(char *buf, double x);

/* printf-style helper on top of FpLogger (defined in fp_model.c). */
void fp_log(const FpLogger *logger, FpStatus status, FpLogCategory category, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 4, 5)))
#endif
    ;

typedef struct {
    const char *model_name;      /* also the FMI modelIdentifier */
    const char *description;
    size_t model_size;           /* sizeof the model struct */
    const FpVar *vars;
    size_t n_vars;
    double default_step;         /* DefaultExperiment stepSize */
    double default_stop;         /* DefaultExperiment stopTime */
    /* Put every variable at its default (start) value and clear the state. */
    void (*set_defaults)(void *model);
    /*
     * Validate parameters and compute the initial state and outputs at t0.
     * Called whenever values are read or initialization ends after a change;
     * must be idempotent.  FP_ERROR means the parameters are unusable (the
     * message names the parameter); FP_WARNING means usable but odd.
     */
    FpStatus (*initialize)(void *model, double t0, const FpLogger *logger);
    /*
     * Advance from t by h.  Must leave the model untouched when it returns
     * FP_ERROR or FP_DISCARD before integrating (e.g. invalid inputs).
     */
    FpStatus (*step)(void *model, double t, double h, const FpLogger *logger);
    /* Re-validate tunable parameters changed while stepping (may be NULL). */
    FpStatus (*tunables_changed)(void *model, const FpLogger *logger);
    /*
     * A model struct from an FMU state, checked before it replaces the live one (the glue
     * passes an aligned copy): structurally sound (sizes and indices within their caps, so
     * stepping it cannot overrun an array) and, when it was saved after initialization
     * (`initialized`), parameters valid by the same rules as initialization and the state
     * finite.  FP_ERROR, with the reason logged, refuses the state.
     */
    FpStatus (*check_restored)(const void *model, int initialized, const FpLogger *logger);
    /*
     * Where in the model struct its int32_t `initialized` marker is (offsetof): kept by the
     * glue, 0 from instantiation and reset on, 1 once initialization has ended
     * (fmi2ExitInitializationMode).  It travels in every FMU state's payload, so a state's
     * lifecycle is checked against the model it holds (fmu_state.h); the model itself
     * never writes it.
     */
    size_t initialized_offset;
    /*
     * The file in the FMU's resources/ folder the model plays back (a signal table,
     * common/fp_table.h), NULL for none.  The glue reads it at instantiation, from
     * fmuResourceLocation, refusing to instantiate (with the file and the reason logged)
     * when it is missing or malformed, and hands it to every callback (FpLogger.table).
     */
    const char *table_resource;
    /* Model Exchange: the model's right-hand side for an importer's solver, NULL for a model
     * that is co-simulation only (below). */
    const struct FpModelExchange *me;
} FpModelInfo;

/*
 * The optional Model Exchange side of a model: its continuous state handed to an importer's
 * solver.  The state is the model's own (the same vector its co-simulation step integrates),
 * exposed by its FP_STATE rows in order, their derivatives by the FP_DERIVATIVE rows; the
 * right-hand side is the one the co-simulation step integrates, at the inputs as that step
 * takes them.  Discontinuities the solver must locate are event indicators (sign changes);
 * a discrete state the model keeps (updated after every internal step in co-simulation) is
 * updated after every completed integrator step and in every event.  No callback allocates.
 */
typedef struct FpModelExchange {
    uint32_t n_states;           /* continuous states (the FP_STATE rows' elements) */
    uint32_t n_event_indicators; /* fixed: the modelDescription's numberOfEventIndicators */
    /* The FP_LOCAL row of n_event_indicators elements that holds them (FMI 3.0 names event
     * indicators by value reference), NULL for none; kept up to date by evaluate. */
    const char *indicators;
    /* After a successful initialize: FP_ERROR (logged, naming the parameter) when the
     * parameters ask for what only the co-simulation step does (e.g. sensor noise drawn per
     * communication step), FP_OK when the model can be integrated by a solver. */
    FpStatus (*check)(const void *model, const FpLogger *logger);
    void (*get_states)(const void *model, double *x);
    void (*set_states)(void *model, const double *x);
    /* A scale of each state (1 where none), for the solver's absolute tolerances. */
    void (*nominals)(const void *model, double *nominal);
    /* The derivatives (kept in the model: get_derivatives), the outputs and everything else
     * computed from the state, at time t and the current state and inputs.  FP_ERROR with
     * the reason logged when an input is unusable (the co-simulation step's input checks). */
    FpStatus (*evaluate)(void *model, double t, const FpLogger *logger);
    void (*get_derivatives)(const void *model, double *dx);
    /* The event indicators at the current state (z), n_event_indicators of them. */
    void (*event_indicators)(const void *model, double *z);
    /* After a completed integrator step, and in Event Mode: the discrete state updated from
     * the continuous one at time t.  FP_ERROR (logged) when the state left the range the model
     * means anything in (as the co-simulation step refuses it). */
    FpStatus (*update_discrete)(void *model, double t, const FpLogger *logger);
} FpModelExchange;

/*
 * The work of one communication step.  A model that subdivides a step (the plant's RK4
 * step, the controller's sample time) keeps that internal step in a fixed Real scalar
 * parameter with one of these names; the FMI layer refuses, before any work, a
 * communication step h that needs more than FP_MAX_INTERNAL_STEPS of them (counted as
 * fp_steps_to_cover(h, step, FP_STEP_TOL * h); 10^6: 500 s per call at the plant's default
 * 0.5 ms, 2000 s at the controller's 2 ms; about a second or two of CPU time per call).
 * A model with none of these parameters is not capped by the FMI layer.
 */
#define FP_INTERNAL_STEP_NAMES {"h_internal", "Ts"}
#define FP_MAX_INTERNAL_STEPS 1000000.0

/*
 * How many of the grid points 0, step, 2 step, ... lie before `span` by more than `tol`:
 * ceil((span - tol) / step), at least 1 when span > tol; 0 when span <= tol (or NaN),
 * infinity when the count is.  The tolerance makes a span meant as a whole multiple n of
 * step count n although rounding put it a hair above (0.002 / 0.0005 is 4 only up to
 * rounding): without it a sliver step would be added, or a grid instant taken one
 * communication step early.  It is FP_STEP_TOL of a step h (the plant's RK4 substeps of h:
 * fp_steps_to_cover(h, h_internal, FP_STEP_TOL * h)), plus FP_TIME_TOL of the absolute
 * times in a span made of them: an importer that sums its steps (t += h) drifts by up to
 * ~1e-17 of t per step (measured at 2 ms: 1.7e-11 after 10^6 steps, 1.6e-10 after 10^7).
 * Beyond the tolerance a grid instant that coincides with a communication point may be
 * taken one communication step early or late: one sample's timing, nothing worse.
 */
#define FP_STEP_TOL 1e-9
#define FP_TIME_TOL 1e-10
double fp_steps_to_cover(double span, double step, double tol);

/*
 * FP_OK when a communication step h is positive and finite and its n internal steps
 * (`what`, e.g. "RK4 steps of h_internal") are at most `cap`; else logs why and FP_ERROR.
 * Called before any work, so a refused step leaves the model untouched.
 */
FpStatus fp_check_step_work(double h, double n, double cap, const char *what,
                            const FpLogger *logger);

/* 64-bit FNV-1a over n bytes, continuing from h (start with FP_FNV1A64_BASIS). */
#define FP_FNV1A64_BASIS 14695981039346656037ULL
uint64_t fp_fnv1a64(uint64_t h, const void *data, size_t n);

/* Each FMU links exactly one model that provides this. */
const FpModelInfo *fp_model_info(void);

/* Number of scalar elements of a table entry. */
static inline uint32_t fp_var_count(const FpVar *v) { return (uint32_t)v->rows * v->cols; }

/*
 * Deterministic GUID derived from the model name and its variable table, so
 * modelDescription.xml and the binary agree without a second source.
 * Written with braces, e.g. "{0123abcd-...}"; buf must hold 40 bytes.
 */
void fp_model_guid(const FpModelInfo *info, char buf[40]);

/* Write the structured name of element k of v (e.g. "pos[2]", "inertia[1,3]"). */
int fp_var_element_name(const FpVar *v, uint32_t k, char *buf, size_t size);

#endif
