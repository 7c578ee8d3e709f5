/*
 * static_master: hover_master (tools/hover_master.c, same script language) with the FMUs
 * linked into the same executable instead of loaded from shared libraries, as a source-code
 * importer or a static embedded target builds them.  Each FMU is compiled from its sources/
 * with FMI2_FUNCTION_PREFIX=<modelIdentifier>_ (fmi2Functions.h then names its functions
 * <modelIdentifier>_fmi2Instantiate, ...; fp_unity_begin.h gives its internal functions the
 * same prefix), and the image is linked from those objects, this file and the maths library:
 *
 *     cc -c -DFMI2_FUNCTION_PREFIX=MultirotorPlant_ -I P/sources P/sources/MultirotorPlant_all.c
 *     cc -c -DFMI2_FUNCTION_PREFIX=FullPoseController_ -I C/sources \
 *        C/sources/FullPoseController_all.c
 *     cc -I P/sources -I fmu_src/tools fmu_src/tools/static_master.c \
 *        MultirotorPlant_all.o FullPoseController_all.o -lm -o static_master
 *
 * In a script, "fmu ID LIBRARY GUID RESOURCE_URI" names the model identifier as LIBRARY.
 * The FMUs linked in: FP_STATIC_FMUS(X), one X(modelIdentifier) each, to be defined on the
 * command line for others than the plant and the controller.  POSIX hosts: the master's
 * dlopen, dlsym, dlclose and dlerror are replaced by a look-up in the table of linked FMUs.
 */
#if defined(_WIN32)
#error "static_master builds on POSIX hosts"
#endif

#define dlopen fp_static_open
#define dlsym fp_static_symbol
#define dlclose fp_static_close
#define dlerror fp_static_error
#include "hover_master.c"

#if !defined(FP_STATIC_FMUS)
#define FP_STATIC_FMUS(X) X(MultirotorPlant) X(FullPoseController)
#endif

/* the functions hover_master looks up */
#define FP_STATIC_FUNCTIONS(P, F)                                                            \
    F(P, fmi2Instantiate) F(P, fmi2FreeInstance) F(P, fmi2SetupExperiment)                   \
    F(P, fmi2EnterInitializationMode) F(P, fmi2ExitInitializationMode) F(P, fmi2Terminate)   \
    F(P, fmi2GetReal) F(P, fmi2SetReal) F(P, fmi2SetInteger) F(P, fmi2SetBoolean)            \
    F(P, fmi2DoStep)
#define FP_STATIC_COUNT 11

#define FP_STATIC_DECLARE(P, name) name##TYPE P##_##name;
#define FP_STATIC_DECLARE_FMU(P) FP_STATIC_FUNCTIONS(P, FP_STATIC_DECLARE)
FP_STATIC_FMUS(FP_STATIC_DECLARE_FMU)

typedef void (*FpStaticFunction)(void);

typedef struct {
    const char *name;
    FpStaticFunction fn;
} FpStaticEntry;

typedef struct {
    const char *model;
    FpStaticEntry functions[FP_STATIC_COUNT];
} FpStaticFmu;

#define FP_STATIC_ENTRY(P, name) {#name, (FpStaticFunction)P##_##name},
#define FP_STATIC_FMU(P) {#P, {FP_STATIC_FUNCTIONS(P, FP_STATIC_ENTRY)}},
static const FpStaticFmu linked[] = {FP_STATIC_FMUS(FP_STATIC_FMU)};

void *fp_static_open(const char *file, int mode) {
    size_t i;
    (void)mode;
    for (i = 0; i < sizeof linked / sizeof linked[0]; i++)
        if (strcmp(linked[i].model, file) == 0) return (void *)&linked[i];
    return NULL;
}

void *fp_static_symbol(void *handle, const char *name) {
    const FpStaticFmu *fmu = (const FpStaticFmu *)handle;
    void *p = NULL;
    int i;
    if (fmu == NULL || sizeof p != sizeof fmu->functions[0].fn) return NULL;
    for (i = 0; i < FP_STATIC_COUNT; i++)
        if (strcmp(fmu->functions[i].name, name) == 0) {
            memcpy(&p, &fmu->functions[i].fn, sizeof p);
            return p;
        }
    return NULL;
}

int fp_static_close(void *handle) {
    (void)handle;
    return 0;
}

char *fp_static_error(void) {
    return "no FMU of that model identifier is linked into this image";
}
