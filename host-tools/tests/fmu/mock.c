/* A small FMI 2.0 co-simulation FMU in C for host-tools/tests/fmu_import.rs:
 * a hammer-like cycle (chamber pressures and acceleration periodic at
 * freq_hz, scaled by the supply pressure) whose `mode` parameter makes it
 * misbehave the ways a foreign FMU can: 1 doStep fails (and logs why
 * through the host's logger, as FMUs do), 2 a NaN output,
 * 3 doStep hangs, 4 doStep crashes, 5 the outputs never cycle. Built
 * with -DNO_RESET it lacks fmi2Reset (a missing FMI function); with
 * -DGUID='"{...}"' it refuses the description's GUID, "{mock}", as a
 * binary rebuilt apart from its description does. Included after
 * `#define FMI2_FUNCTION_PREFIX mock_` it is a source-code FMU's file: its
 * functions named with the model identifier as FMI 2.0 asks of sources
 * (the test's `hammer fmu compile` gives the binary the standard names). It prints
 * to standard output at initialisation, as FMUs do.
 * Value references: 0 supply_bar, 1 freq_hz, 2 mode (Integer),
 * 3 derived (calculatedParameter), 10 p_rear, 11 p_front, 12 accel. */
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

typedef void *fmi2Component;
typedef int fmi2Status;
typedef unsigned int fmi2ValueReference;

#ifdef FMI2_FUNCTION_PREFIX
#define PASTE_(a, b) a##b
#define PASTE(a, b) PASTE_(a, b)
#define fmi2GetVersion PASTE(FMI2_FUNCTION_PREFIX, fmi2GetVersion)
#define fmi2GetTypesPlatform PASTE(FMI2_FUNCTION_PREFIX, fmi2GetTypesPlatform)
#define fmi2Instantiate PASTE(FMI2_FUNCTION_PREFIX, fmi2Instantiate)
#define fmi2FreeInstance PASTE(FMI2_FUNCTION_PREFIX, fmi2FreeInstance)
#define fmi2SetDebugLogging PASTE(FMI2_FUNCTION_PREFIX, fmi2SetDebugLogging)
#define fmi2SetupExperiment PASTE(FMI2_FUNCTION_PREFIX, fmi2SetupExperiment)
#define fmi2EnterInitializationMode PASTE(FMI2_FUNCTION_PREFIX, fmi2EnterInitializationMode)
#define fmi2ExitInitializationMode PASTE(FMI2_FUNCTION_PREFIX, fmi2ExitInitializationMode)
#define fmi2Terminate PASTE(FMI2_FUNCTION_PREFIX, fmi2Terminate)
#define fmi2Reset PASTE(FMI2_FUNCTION_PREFIX, fmi2Reset)
#define fmi2SetReal PASTE(FMI2_FUNCTION_PREFIX, fmi2SetReal)
#define fmi2SetInteger PASTE(FMI2_FUNCTION_PREFIX, fmi2SetInteger)
#define fmi2SetBoolean PASTE(FMI2_FUNCTION_PREFIX, fmi2SetBoolean)
#define fmi2GetReal PASTE(FMI2_FUNCTION_PREFIX, fmi2GetReal)
#define fmi2GetInteger PASTE(FMI2_FUNCTION_PREFIX, fmi2GetInteger)
#define fmi2GetBoolean PASTE(FMI2_FUNCTION_PREFIX, fmi2GetBoolean)
#define fmi2DoStep PASTE(FMI2_FUNCTION_PREFIX, fmi2DoStep)
#endif

#ifndef GUID
#define GUID "{mock}"
#endif

/* fmi2CallbackFunctions, as far as the logger and the environment. */
typedef struct {
    void (*logger)(void *env, const char *instance, fmi2Status status, const char *category, const char *message, ...);
    void *allocate, *free, *step_finished;
    void *env;
} Callbacks;

typedef struct {
    double supply_bar, freq_hz, t, out[3];
    int mode;
    const Callbacks *cb;
} Mock;

static void outputs(Mock *m) {
    double w = 2.0 * 3.141592653589793 * m->freq_hz * m->t;
    double p = m->supply_bar * 1e5;
    if (m->mode == 5) w = 0.0;
    m->out[0] = 0.5 * p * (1.0 + sin(w));
    m->out[1] = 0.5 * p * (1.0 - sin(w));
    m->out[2] = 100.0 * cos(w);
    if (m->mode == 2 && m->t > 0.01) m->out[1] = NAN;
}

const char *fmi2GetVersion(void) { return "2.0"; }
const char *fmi2GetTypesPlatform(void) { return "default"; }

fmi2Component fmi2Instantiate(const char *name, int type, const char *guid, const char *res, const void *cb, int vis, int log) {
    (void)type; (void)res; (void)vis; (void)log;
    const Callbacks *callbacks = cb;
    if (strcmp(guid, GUID) != 0) {
        callbacks->logger(callbacks->env, name, 3, "logStatusError", "Wrong GUID.");
        return NULL;
    }
    Mock *m = calloc(1, sizeof(Mock));
    m->cb = cb;
    m->supply_bar = 5.0;
    m->freq_hz = 40.0;
    return m;
}
void fmi2FreeInstance(fmi2Component c) { free(c); }
fmi2Status fmi2SetDebugLogging(fmi2Component c, int on, size_t n, const char *const *cat) { (void)c; (void)on; (void)n; (void)cat; return 0; }
fmi2Status fmi2SetupExperiment(fmi2Component c, int tol_on, double tol, double t0, int stop_on, double stop) {
    (void)tol_on; (void)tol; (void)stop_on; (void)stop;
    ((Mock *)c)->t = t0;
    return 0;
}
fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return 0; }
/* Prints to standard output, as FMUs do: the protocol must not see it. */
fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    printf("mock: initialised\n");
    fflush(stdout);
    outputs(c);
    return 0;
}
fmi2Status fmi2Terminate(fmi2Component c) { (void)c; return 0; }
#ifndef NO_RESET
fmi2Status fmi2Reset(fmi2Component c) {
    Mock *m = c;
    m->supply_bar = 5.0;
    m->freq_hz = 40.0;
    m->mode = 0;
    m->t = 0.0;
    return 0;
}
#endif

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference *vr, size_t n, const double *v) {
    Mock *m = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == 0) m->supply_bar = v[i];
        else if (vr[i] == 1) m->freq_hz = v[i];
        else return 3;
    }
    return 0;
}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference *vr, size_t n, const int *v) {
    Mock *m = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == 2) m->mode = v[i];
        else return 3;
    }
    return 0;
}
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference *vr, size_t n, const int *v) { (void)c; (void)vr; (void)v; return n ? 3 : 0; }
fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference *vr, size_t n, double *v) {
    Mock *m = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] >= 10 && vr[i] <= 12) v[i] = m->out[vr[i] - 10];
        else if (vr[i] == 0) v[i] = m->supply_bar;
        else if (vr[i] == 3) v[i] = 2.0 * m->supply_bar;
        else return 3;
    }
    return 0;
}
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference *vr, size_t n, int *v) {
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == 2) v[i] = ((Mock *)c)->mode;
        else return 3;
    }
    return 0;
}
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference *vr, size_t n, int *v) { (void)c; (void)vr; (void)v; return n ? 3 : 0; }

fmi2Status fmi2DoStep(fmi2Component c, double t, double h, int no_set) {
    Mock *m = c;
    (void)no_set;
    if (m->t > 0.02) {
        if (m->mode == 1) {
            m->cb->logger(m->cb->env, "mock", 3, "logStatusError", "the valve's solver did not converge");
            return 3;
        }
        if (m->mode == 3) for (;;) pause();
        if (m->mode == 4) raise(SIGSEGV);
    }
    m->t = t + h;
    outputs(m);
    return 0;
}
