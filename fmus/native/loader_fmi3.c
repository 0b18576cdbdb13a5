/*
 * The FMI 3.0 LOADER: binaries/<platform tuple>/<model>.so of every obsfmu FMI 3.0 FMU
 * (details: docs/fmi3.md; the FMI 2.0 loader is loader.c, what both share loader_common.h).
 *
 * Plain C, compiled without Python headers: it dlopens cleanly (RTLD_NOW) in any process, finds or
 * starts Python and loads the BRIDGE exactly like the FMI 2.0 loader (loader_common.h), and
 * translates FMI 3.0 into the bridge's FMI 2.0 calls on the slave's scalar value references:
 *
 *   1. Variables: an FMI 3.0 variable (an array such as x_hat[3] or A[3,3], or a scalar) is a
 *      list of the slave's scalar value references, read from resources/obsfmu_fmi3.txt (written
 *      by fmus/fmi3 from the same definition as the FMI 2.0 names).  Float64 <-> fmi2GetReal/SetReal,
 *      Int32 <-> fmi2GetInteger/SetInteger; `time` (the independent variable) is answered here.
 *   2. The FMI 3.0 co-simulation state machine (no event mode: hasEventMode = false): instantiated,
 *      initializationMode, stepMode, intermediateUpdateMode, terminated.  A call it refuses returns
 *      fmi3Error, logs the call and the reason, and changes nothing; so does a call the slave
 *      refuses (fmi3Error, nothing changed: bad FMU-state bytes, an invalid Int32 value, ...).  A
 *      call that FAILS inside the slave (fmi3Error: an unexpected exception, an error the slave
 *      logged) leads to terminated, left by fmi3SetFMUState, fmi3Reset or fmi3FreeInstance.
 *      fmi3Discard from fmi3DoStep leaves the FMU in step mode at the same time (the slave kept its
 *      state), lastSuccessfulTime = that time.
 *   3. Input interpolation: when the importer gives an intermediateUpdate callback and requires
 *      inputs (requiredIntermediateVariables), fmi3DoStep calls it once at t + h asking for those
 *      inputs (intermediateVariableSetRequested); the values set there and the values at t define
 *      the slope the slave integrates with -- what fmi2SetRealInputDerivatives does in FMI 2.0.
 *      Without it the slave's <port>_interpolation parameters decide, as in FMI 2.0.
 *   4. Status rule: the worst of the call's own result and of what the slave logged during it,
 *      capped at fmi3Error (the bridge's rule).  Debug messages (status OK) go to logMessage only while
 *      logging is on; warnings, discards and errors always (as the FMI 2.0 binary and the Reference FMUs do:
 *      fmusim leaves logging off, and a discarded step then said nothing).
 */
#define _GNU_SOURCE /* dl_iterate_phdr */
#include "fmi3Functions.h"
#include "loader_common.h"

#define TABLE "obsfmu_fmi3.txt"

typedef char check_int32_is_fmi2Integer[sizeof(fmi3Int32) == sizeof(fmi2Integer) ? 1 : -1];

/* ------------------------------------------------------------------ state machine */

enum {
    INSTANTIATED = 1,
    INITIALIZATION_MODE = 2,
    STEP_MODE = 4,
    INTERMEDIATE_UPDATE_MODE = 8, /* inside the intermediateUpdate callback, during fmi3DoStep */
    TERMINATED = 16,
};

#define ANY_STATE (INSTANTIATED | INITIALIZATION_MODE | STEP_MODE | INTERMEDIATE_UPDATE_MODE | TERMINATED)
#define STATE_SETTABLE (INSTANTIATED | INITIALIZATION_MODE | STEP_MODE | TERMINATED) /* FMU state, reset */
#define READABLE (INSTANTIATED | INITIALIZATION_MODE | STEP_MODE | TERMINATED)
#define WRITABLE (INSTANTIATED | INITIALIZATION_MODE | STEP_MODE | INTERMEDIATE_UPDATE_MODE)
#define NO_STATE 0

static const char *state_name(unsigned state)
{
    switch (state) {
    case INSTANTIATED: return "instantiated";
    case INITIALIZATION_MODE: return "initializationMode";
    case STEP_MODE: return "stepMode";
    case INTERMEDIATE_UPDATE_MODE: return "intermediateUpdateMode";
    default: return "terminated";
    }
}

static const Version FMI3 = {3, ANY_STATE, INSTANTIATED | INITIALIZATION_MODE, STEP_MODE | TERMINATED, TERMINATED,
                             state_name, "fmi3"};

/* ------------------------------------------------------------------ variables */

typedef struct {
    char type;                      /* 'F' Float64, 'I' Int32 */
    char causality;                 /* 't' independent (time), 'p' parameter, 'i' input, 'o' output */
    char *name;
    size_t count;                   /* number of elements */
    fmi2ValueReference *scalars;    /* the slave's value reference of each element (row-major) */
    size_t offset;                  /* inputs: where its elements are in the intermediate buffers */
    int required;                   /* inputs: in requiredIntermediateVariables */
    int pending;                    /* inputs: set during the current intermediate update */
} Variable;

typedef struct {
    Core core;                      /* first: what both loaders share */
    Variable *variables;            /* indexed by FMI 3.0 value reference */
    size_t variable_count;
    size_t scalar_count, input_count;
    fmi2ValueReference *scratch;    /* scalar value references of one call (scalar_count) */
    /* intermediate update: the inputs set at t + h, then (slave vrs, values at t, slopes, orders) */
    double *ends, *starts, *slopes;
    fmi2Integer *orders;
    fmi2ValueReference *input_vrs;
    size_t derived;                 /* how many of input_vrs got derivatives in this step's intermediate update */
    fmi3InstanceEnvironment environment;
    fmi3LogMessageCallback logMessage;
    fmi3IntermediateUpdateCallback intermediateUpdate;
    int logging_on;
} Instance;

static void free_table(Instance *c)
{
    for (size_t i = 0; c->variables && i < c->variable_count; i++) {
        free(c->variables[i].name);
        free(c->variables[i].scalars);
    }
    free(c->variables);
    free(c->scratch);
    free(c->ends);
    free(c->starts);
    free(c->slopes);
    free(c->orders);
    free(c->input_vrs);
}

/* Lines "<vr> <F|I> <t|p|i|o> <name> <count> <scalar vr>..." (value references 0, 1, 2, ... in order). */
static int read_table(Instance *c, const char *resources, char *message, size_t size)
{
    char path[PATH_SIZE + 32];
    snprintf(path, sizeof path, "%s/" TABLE, resources);
    FILE *file = obsfmu_fopen(path, "r");
    if (file == NULL) {
        snprintf(message, size, "cannot read %s: not an obsfmu FMI 3.0 FMU", path);
        return -1;
    }
    char *line = NULL;
    size_t capacity = 0;
    int failed = 0;
    while (!failed && read_line(&line, &capacity, file) != -1) { /* lines grow with the arrays (A of n x n) */
        if (line[0] == '#' || line[0] == '\n') continue;
        unsigned vr;
        char type, causality, name[256];
        size_t count;
        int used = 0;
        if (sscanf(line, "%u %c %c %255s %zu%n", &vr, &type, &causality, name, &count, &used) != 5
            || vr != c->variable_count || count > 1000000) {
            failed = 1;
            break;
        }
        Variable *grown = realloc(c->variables, (c->variable_count + 1) * sizeof(Variable));
        if (grown == NULL) { failed = 1; break; }
        c->variables = grown;
        Variable *v = &c->variables[c->variable_count++];
        memset(v, 0, sizeof *v);
        v->type = type;
        v->causality = causality;
        v->name = malloc(strlen(name) + 1);
        v->scalars = calloc(count ? count : 1, sizeof(fmi2ValueReference));
        if (v->name == NULL || v->scalars == NULL) { failed = 1; break; }
        strcpy(v->name, name);
        v->count = count;
        const char *cursor = line + used;
        for (size_t k = 0; k < count; k++) {
            unsigned scalar;
            if (sscanf(cursor, "%u%n", &scalar, &used) != 1) { failed = 1; break; }
            v->scalars[k] = scalar;
            cursor += used;
        }
        if (causality == 'i') {
            v->offset = c->input_count;
            c->input_count += count;
        }
        c->scalar_count += count;
    }
    fclose(file);
    if (failed || c->variable_count == 0) {
        snprintf(message, size, "%s is damaged (line: %.200s)", path, line ? line : "");
        free(line);
        return -1;
    }
    free(line);
    size_t inputs = c->input_count ? c->input_count : 1;
    c->scratch = calloc(c->scalar_count ? c->scalar_count : 1, sizeof(fmi2ValueReference));
    c->ends = calloc(inputs, sizeof(double));
    c->starts = calloc(inputs, sizeof(double));
    c->slopes = calloc(inputs, sizeof(double));
    c->orders = calloc(inputs, sizeof(fmi2Integer));
    c->input_vrs = calloc(inputs, sizeof(fmi2ValueReference));
    if (!c->scratch || !c->ends || !c->starts || !c->slopes || !c->orders || !c->input_vrs) {
        snprintf(message, size, "out of memory");
        return -1;
    }
    return 0;
}

/* ------------------------------------------------------------------ logging */

/* The bridge's and the loader's messages (fmi2 logger signature, message pre-formatted with '%'
 * doubled) -> logMessage, with '#' escaped as '##' (FMI 3.0: '#' quotes value references). */
static void relay(fmi2ComponentEnvironment environment, fmi2String name, fmi2Status status, fmi2String category,
                  fmi2String message, ...)
{
    (void)name;
    Instance *c = (Instance *)environment;
    if (c == NULL || c->logMessage == NULL || (!c->logging_on && status == fmi2OK)) return;
    char text[8192], escaped[16384];
    va_list arguments;
    va_start(arguments, message);
    vsnprintf(text, sizeof text, message, arguments);
    va_end(arguments);
    size_t j = 0;
    for (size_t i = 0; text[i] && j + 2 < sizeof escaped; i++) {
        if (text[i] == '#') escaped[j++] = '#';
        escaped[j++] = text[i];
    }
    escaped[j] = '\0';
    c->logMessage(c->environment, (fmi3Status)status, category, escaped);
}

#define REFUSE(c, ...) ((fmi3Status)refuse(&(c)->core, __VA_ARGS__))

/* The instance, or fmi3Error when it is not one this FMU issued and has not freed (no logger is known
 * then: nothing is logged), or when the call is not allowed in its state (nothing changes). */
#define ENTER(call, allowed)                                                                           \
    Instance *c = (Instance *)instance;                                                                \
    if (!handle_known(&instances, c)) return fmi3Error;                                                \
    if (!(c->core.state & (allowed)))                                                                  \
        return REFUSE(c, "%s is not allowed in state %s", #call, state_name(c->core.state));

#define AFTER(c, status) ((fmi3Status)after(&(c)->core, (status)))

/* ------------------------------------------------------------------ instantiation */

const char *fmi3GetVersion(void) { return fmi3Version; }

static void free_instance(Instance *c)
{
    if (c == NULL) return;
    free_table(c);
    core_free(&c->core);
    free(c);
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate)
{
    (void)earlyReturnAllowed; /* this FMU never returns early */
    const char *name = instanceName ? instanceName : "";
    char message[8192];
    Instance *c = calloc(1, sizeof(Instance));
    if (c == NULL) return NULL;
    c->environment = instanceEnvironment;
    c->logMessage = logMessage;
    c->intermediateUpdate = intermediateUpdate;
    c->logging_on = 1; /* the reason of a failed instantiation is always given */
    fmi2CallbackFunctions callbacks = {relay, NULL, NULL, NULL, c};
    c->core.callbacks = callbacks;
    char *resources = NULL, *record = NULL;
    if (resourcePath == NULL) {
        say(&callbacks, name, fmi2Error, "fmi3InstantiateCoSimulation: resourcePath is required");
        goto failed;
    }
    if (eventModeUsed) {
        say(&callbacks, name, fmi2Error, "fmi3InstantiateCoSimulation: eventModeUsed = true, but this FMU has no "
            "event mode (hasEventMode = false)");
        goto failed;
    }
    resources = obsfmu_resource_path(resourcePath);
    record = checked_record(&callbacks, name, "fmi3InstantiateCoSimulation", resources, resourcePath,
                            instantiationToken, "instantiationToken");
    if (record == NULL) goto failed;
    if (read_table(c, resources, message, sizeof message) != 0) {
        say(&callbacks, name, fmi2Error, "fmi3InstantiateCoSimulation: %s", message);
        goto failed;
    }
    if (nRequiredIntermediateVariables > 0 && requiredIntermediateVariables == NULL) {
        say(&callbacks, name, fmi2Error, "fmi3InstantiateCoSimulation: requiredIntermediateVariables is NULL");
        goto failed;
    }
    for (size_t i = 0; i < nRequiredIntermediateVariables; i++) {
        fmi3ValueReference vr = requiredIntermediateVariables[i];
        if (vr >= c->variable_count || c->variables[vr].causality != 'i') {
            say(&callbacks, name, fmi2Error, "fmi3InstantiateCoSimulation: required intermediate variable %u %s: only "
                "inputs have intermediateUpdate = true (this FMU gives no intermediate outputs)", vr,
                vr < c->variable_count ? c->variables[vr].name : "does not exist");
            goto failed;
        }
        c->variables[vr].required = 1;
    }
    const ObsfmuBridge *functions_of_bridge = get_bridge(resources, record, message, sizeof message);
    if (functions_of_bridge == NULL) {
        say(&callbacks, name, fmi2Error, "fmi3InstantiateCoSimulation: %s", message);
        goto failed;
    }
    fmi2Component inner = functions_of_bridge->instantiate(name, fmi2CoSimulation, instantiationToken, resourcePath,
                                                           &c->core.callbacks, visible, loggingOn);
    if (inner == NULL) goto failed; /* the bridge logged why */
    if (core_init(&c->core, &FMI3, functions_of_bridge, inner, name, INSTANTIATED, resources) != 0
        || handle_add(&instances, c, NULL) != 0) {
        functions_of_bridge->freeInstance(inner);
        goto failed;
    }
    c->logging_on = loggingOn;
    free(record);
    free(resources);
    return c;
failed:
    free(record);
    free(resources);
    free_instance(c);
    return NULL;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment, fmi3LogMessageCallback logMessage)
{
    (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    if (logMessage) logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                               "fmi3InstantiateModelExchange: this FMU supports co-simulation only");
    (void)instanceName;
    return NULL;
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption)
{
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    (void)clockUpdate; (void)lockPreemption; (void)unlockPreemption;
    if (logMessage) logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                               "fmi3InstantiateScheduledExecution: this FMU supports co-simulation only");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance)
{
    Instance *c = (Instance *)instance;
    if (!handle_known(&instances, c)) return; /* NULL, not this FMU's, or freed already: nothing to do */
    if (c->core.state == INTERMEDIATE_UPDATE_MODE) { /* from inside its own fmi3DoStep: refused */
        say(&c->core.callbacks, c->core.name, fmi2Error,
            "fmi3FreeInstance is not allowed in state intermediateUpdateMode (inside fmi3DoStep)");
        return;
    }
    handle_remove(&instances, c);
    core_free_states(&c->core);
    c->core.bridge->freeInstance(c->core.inner);
    free_instance(c);
}

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[])
{
    ENTER(fmi3SetDebugLogging, ANY_STATE)
    c->logging_on = loggingOn;
    return AFTER(c, c->core.bridge->setDebugLogging(c->core.inner, loggingOn, nCategories, categories));
}

/* ------------------------------------------------------------------ modes */

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    ENTER(fmi3EnterInitializationMode, INSTANTIATED)
    if (!finite(startTime)) return REFUSE(c, "fmi3EnterInitializationMode: startTime %g is not finite", startTime);
    fmi2Status status = c->core.bridge->setupExperiment(c->core.inner, toleranceDefined, tolerance, startTime,
                                                        stopTimeDefined, stopTime);
    if (status < fmi2Error) {
        fmi2Status entered = c->core.bridge->enterInitializationMode(c->core.inner);
        status = entered > status ? entered : status;
    }
    if (status < fmi2Error) {
        c->core.time = startTime;
        c->core.state = INITIALIZATION_MODE;
    }
    return AFTER(c, status);
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance)
{
    ENTER(fmi3ExitInitializationMode, INITIALIZATION_MODE)
    fmi2Status status = c->core.bridge->exitInitializationMode(c->core.inner);
    if (status < fmi2Error) c->core.state = STEP_MODE;
    return AFTER(c, status);
}

fmi3Status fmi3Terminate(fmi3Instance instance)
{
    ENTER(fmi3Terminate, STEP_MODE)
    fmi2Status status = c->core.bridge->terminate(c->core.inner);
    if (status < fmi2Error) c->core.state = TERMINATED;
    return AFTER(c, status);
}

fmi3Status fmi3Reset(fmi3Instance instance)
{
    ENTER(fmi3Reset, STATE_SETTABLE)
    return (fmi3Status)core_reset(&c->core, INSTANTIATED);
}

/* ------------------------------------------------------------------ values */

static const char *type_name(char type) { return type == 'F' ? "Float64" : type == 'I' ? "Int32" : "?"; }

/* Check the value references of a get/set of `type` and put their scalars in c->scratch; the number
 * of scalars in *total, 1 in *has_time when `time` is among them.  fmi3Error (logged) when a value
 * reference does not exist, has another type, cannot be set in this state, or nValues does not match. */
static fmi3Status resolve(Instance *c, const char *call, const fmi3ValueReference vr[], size_t nvr, char type,
                          size_t nValues, int setting, size_t *total, int *has_time)
{
    size_t n = 0, scalars = 0; /* values; the slave's scalars among them (all but `time`) */
    *has_time = 0;
    if (nvr > c->variable_count) /* before vr[] is read: an nvr of 2^40 is not an array of that length */
        return REFUSE(c, "%s: nvr %zu larger than the FMU's variables (%zu)", call, nvr, c->variable_count);
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] >= c->variable_count)
            return REFUSE(c, "%s: value reference %u does not exist", call, vr[i]);
        Variable *v = &c->variables[vr[i]];
        if (v->type != type)
            return REFUSE(c, "%s: %s (value reference %u) is %s, not %s", call, v->name, vr[i], type_name(v->type),
                          type_name(type));
        if (setting) {
            unsigned state = c->core.state;
            if (v->causality == 't' || v->causality == 'o')
                return REFUSE(c, "%s: %s is %s: it cannot be set", call, v->name,
                              v->causality == 't' ? "the independent variable" : "an output");
            if (v->causality == 'p' && (state & (STEP_MODE | INTERMEDIATE_UPDATE_MODE)))
                return REFUSE(c, "%s: %s is a fixed parameter: it can be set only before fmi3ExitInitializationMode "
                              "(state %s)", call, v->name, state_name(state));
            if (state == INTERMEDIATE_UPDATE_MODE && !v->required)
                return REFUSE(c, "%s: %s is not in requiredIntermediateVariables: it cannot be set in "
                              "intermediateUpdateMode", call, v->name);
        }
        if (v->causality == 't') {
            *has_time = 1;
            n += 1;
            continue;
        }
        if (scalars + v->count <= c->scalar_count)
            memcpy(c->scratch + scalars, v->scalars, v->count * sizeof(fmi2ValueReference));
        n += v->count;
        scalars += v->count;
    }
    if (n != nValues)
        return REFUSE(c, "%s: nValues is %zu, but the %zu value references hold %zu values", call, nValues, nvr, n);
    if (scalars > c->scalar_count) /* a variable listed twice or more (`time` is not one of the slave's) */
        return REFUSE(c, "%s: %zu values requested, more than the FMU's %zu: list each variable once", call,
                      scalars + *has_time, c->scalar_count + 1);
    *total = n;
    return fmi3OK;
}

#define ARRAYS(call, vr, nvr, values, nValues)                                                              \
    if (((nvr) > 0 && (vr) == NULL) || ((nValues) > 0 && (values) == NULL))                                 \
        return REFUSE(c, "%s: NULL value references or values (%zu, %zu)", #call, (size_t)(nvr), (size_t)(nValues));

/* Getters: one bridge call for all scalars; `time` (only Float64) is filled in here. */
#define GETTER(call, type_letter, type, bridge_get, bridge_type)                                            \
    fmi3Status call(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, type values[], size_t nValues) \
    {                                                                                                       \
        ENTER(call, READABLE)                                                                               \
        ARRAYS(call, vr, nvr, values, nValues)                                                              \
        size_t total;                                                                                       \
        int has_time;                                                                                       \
        fmi3Status status = resolve(c, #call, vr, nvr, type_letter, nValues, 0, &total, &has_time);         \
        if (status != fmi3OK) return status;                                                                \
        if (!has_time)                                                                                      \
            return AFTER(c, c->core.bridge->bridge_get(c->core.inner, c->scratch, total, (bridge_type *)values)); \
        fmi2Status worst = fmi2OK;                                                                          \
        for (size_t i = 0, at = 0; i < nvr; i++) {                                                          \
            Variable *v = &c->variables[vr[i]];                                                             \
            if (v->causality == 't') {                                                                      \
                values[at++] = (type)c->core.time;                                                          \
                continue;                                                                                   \
            }                                                                                               \
            fmi2Status s = c->core.bridge->bridge_get(c->core.inner, v->scalars, v->count, (bridge_type *)values + at); \
            worst = s > worst ? s : worst;                                                                  \
            at += v->count;                                                                                 \
            if (worst >= fmi2Error) break;                                                                  \
        }                                                                                                   \
        return AFTER(c, worst);                                                                             \
    }

GETTER(fmi3GetFloat64, 'F', fmi3Float64, getReal, fmi2Real)
GETTER(fmi3GetInt32, 'I', fmi3Int32, getInteger, fmi2Integer)

/* Inputs set inside the intermediate update are kept here until fmi3DoStep turns them into slopes. */
static void keep_intermediate(Instance *c, const fmi3ValueReference vr[], size_t nvr, const fmi3Float64 values[])
{
    for (size_t i = 0, at = 0; i < nvr; i++) {
        Variable *v = &c->variables[vr[i]];
        memcpy(c->ends + v->offset, values + at, v->count * sizeof(double));
        v->pending = 1;
        at += v->count;
    }
}

#define SETTER(call, type_letter, type, bridge_set, bridge_type, intermediate)                              \
    fmi3Status call(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const type values[],   \
                    size_t nValues)                                                                         \
    {                                                                                                       \
        ENTER(call, WRITABLE)                                                                               \
        ARRAYS(call, vr, nvr, values, nValues)                                                              \
        size_t total;                                                                                       \
        int has_time;                                                                                       \
        fmi3Status status = resolve(c, #call, vr, nvr, type_letter, nValues, 1, &total, &has_time);         \
        if (status != fmi3OK) return status;                                                                \
        if (c->core.state == INTERMEDIATE_UPDATE_MODE) {                                                    \
            intermediate;                                                                                   \
            return fmi3OK;                                                                                  \
        }                                                                                                   \
        return AFTER(c, c->core.bridge->bridge_set(c->core.inner, c->scratch, total, (const bridge_type *)values)); \
    }

SETTER(fmi3SetFloat64, 'F', fmi3Float64, setReal, fmi2Real, keep_intermediate(c, vr, nvr, values))
SETTER(fmi3SetInt32, 'I', fmi3Int32, setInteger, fmi2Integer, (void)0) /* Int32 inputs: none (never required) */

/* Types this FMU has no variables of: a call naming a value reference is refused. */
#define NO_VARIABLES(call, value_type, allowed, constness)                                                  \
    fmi3Status call(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, constness value_type values[], \
                    size_t nValues)                                                                         \
    {                                                                                                       \
        (void)values; (void)nValues;                                                                        \
        ENTER(call, allowed)                                                                                \
        if (nvr == 0) return fmi3OK;                                                                        \
        if (vr == NULL) return REFUSE(c, "%s: NULL value references", #call);                              \
        if (vr[0] < c->variable_count)                                                                      \
            return REFUSE(c, "%s: %s (value reference %u) is %s", #call, c->variables[vr[0]].name, vr[0],   \
                          type_name(c->variables[vr[0]].type));                                             \
        return REFUSE(c, "%s: value reference %u does not exist", #call, vr[0]);                           \
    }
#define NO_GETTER(call, value_type) NO_VARIABLES(call, value_type, READABLE, )
#define NO_SETTER(call, value_type) NO_VARIABLES(call, value_type, WRITABLE, const)

NO_GETTER(fmi3GetFloat32, fmi3Float32)
NO_GETTER(fmi3GetInt8, fmi3Int8)
NO_GETTER(fmi3GetUInt8, fmi3UInt8)
NO_GETTER(fmi3GetInt16, fmi3Int16)
NO_GETTER(fmi3GetUInt16, fmi3UInt16)
NO_GETTER(fmi3GetUInt32, fmi3UInt32)
NO_GETTER(fmi3GetInt64, fmi3Int64)
NO_GETTER(fmi3GetUInt64, fmi3UInt64)
NO_GETTER(fmi3GetBoolean, fmi3Boolean)
NO_GETTER(fmi3GetString, fmi3String)
NO_SETTER(fmi3SetFloat32, fmi3Float32)
NO_SETTER(fmi3SetInt8, fmi3Int8)
NO_SETTER(fmi3SetUInt8, fmi3UInt8)
NO_SETTER(fmi3SetInt16, fmi3Int16)
NO_SETTER(fmi3SetUInt16, fmi3UInt16)
NO_SETTER(fmi3SetUInt32, fmi3UInt32)
NO_SETTER(fmi3SetInt64, fmi3Int64)
NO_SETTER(fmi3SetUInt64, fmi3UInt64)
NO_SETTER(fmi3SetBoolean, fmi3Boolean)
NO_SETTER(fmi3SetString, fmi3String)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, size_t valueSizes[],
                         fmi3Binary values[], size_t nValues)
{
    (void)valueSizes; (void)values; (void)nValues;
    ENTER(fmi3GetBinary, READABLE)
    return nvr == 0 ? fmi3OK : REFUSE(c, "fmi3GetBinary: this FMU has no Binary variables (value reference %u)",
                                      vr ? vr[0] : 0);
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const size_t valueSizes[],
                         const fmi3Binary values[], size_t nValues)
{
    (void)valueSizes; (void)values; (void)nValues;
    ENTER(fmi3SetBinary, WRITABLE)
    return nvr == 0 ? fmi3OK : REFUSE(c, "fmi3SetBinary: this FMU has no Binary variables (value reference %u)",
                                      vr ? vr[0] : 0);
}

/* ------------------------------------------------------------------ FMU state (loader_common.h) */

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *state)
{
    ENTER(fmi3GetFMUState, STATE_SETTABLE)
    return (fmi3Status)core_get_state(&c->core, "fmi3GetFMUState", state);
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState state)
{
    ENTER(fmi3SetFMUState, STATE_SETTABLE)
    return (fmi3Status)core_set_state(&c->core, "fmi3SetFMUState", state);
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *state)
{
    ENTER(fmi3FreeFMUState, STATE_SETTABLE)
    return (fmi3Status)core_free_state(&c->core, "fmi3FreeFMUState", state);
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState state, size_t *size)
{
    ENTER(fmi3SerializedFMUStateSize, STATE_SETTABLE)
    return (fmi3Status)core_serialized_size(&c->core, "fmi3SerializedFMUStateSize", state, size);
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState state, fmi3Byte serializedState[], size_t size)
{
    ENTER(fmi3SerializeFMUState, STATE_SETTABLE)
    return (fmi3Status)core_serialize(&c->core, "fmi3SerializeFMUState", state, (fmi2Byte *)serializedState, size);
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *state)
{
    ENTER(fmi3DeserializeFMUState, STATE_SETTABLE)
    return (fmi3Status)core_deserialize(&c->core, "fmi3DeserializeFMUState", (const fmi2Byte *)serializedState, size,
                                        state);
}

/* ------------------------------------------------------------------ stepping */

/* The intermediate update at t + h: the required inputs set there become the slopes of the step
 * (u(t + s) = u(t) + s (u(t + h) - u(t)) / h), handed to the slave as first input derivatives. */
static fmi2Status intermediate_inputs(Instance *c, double t, double h)
{
    int any = 0;
    c->derived = 0;
    for (size_t i = 0; i < c->variable_count; i++) {
        c->variables[i].pending = 0;
        any |= c->variables[i].required;
    }
    if (c->intermediateUpdate == NULL || !any) return fmi2OK;
    fmi3Boolean early = fmi3False;
    fmi3Float64 early_time = t + h;
    c->core.state = INTERMEDIATE_UPDATE_MODE;
    c->intermediateUpdate(c->environment, t + h, fmi3True, fmi3False, fmi3False, fmi3False, &early, &early_time);
    c->core.state = STEP_MODE;
    size_t n = 0;
    for (size_t i = 0; i < c->variable_count; i++) {
        Variable *v = &c->variables[i];
        if (!v->pending) continue;
        memcpy(c->input_vrs + n, v->scalars, v->count * sizeof(fmi2ValueReference));
        memmove(c->slopes + n, c->ends + v->offset, v->count * sizeof(double)); /* the ends, for now */
        n += v->count;
    }
    if (n == 0) return fmi2OK;
    fmi2Status status = c->core.bridge->getReal(c->core.inner, c->input_vrs, n, c->starts);
    if (status >= fmi2Error) return status;
    for (size_t k = 0; k < n; k++) {
        c->slopes[k] = (c->slopes[k] - c->starts[k]) / h;
        c->orders[k] = 1;
    }
    fmi2Status set = c->core.bridge->setRealInputDerivatives(c->core.inner, c->input_vrs, n, c->orders, c->slopes);
    c->derived = n;
    return set > status ? set : status;
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn,
                      fmi3Float64 *lastSuccessfulTime)
{
    ENTER(fmi3DoStep, STEP_MODE)
    double t = currentCommunicationPoint, h = communicationStepSize, now = c->core.time;
    if (!eventHandlingNeeded || !terminateSimulation || !earlyReturn || !lastSuccessfulTime)
        return REFUSE(c, "fmi3DoStep: NULL output argument");
    if (check_step(&c->core, "fmi3DoStep", t, h) != fmi2OK) return fmi3Error;
    *eventHandlingNeeded = fmi3False;
    *terminateSimulation = fmi3False;
    *earlyReturn = fmi3False;
    *lastSuccessfulTime = now;
    fmi2Status status = intermediate_inputs(c, t, h);
    if (status < fmi2Discard) {
        fmi2Status stepped = c->core.bridge->doStep(c->core.inner, t, h, noSetFMUStatePriorToCurrentPoint);
        status = stepped > status ? stepped : status;
    }
    if (status <= fmi2Warning) {
        c->core.time = t + h;
        *lastSuccessfulTime = c->core.time;
    } else if (status == fmi2Discard && c->derived > 0) { /* the slopes were this step's: take them back */
        fmi2Status cleared = c->core.bridge->clearInputDerivatives(c->core.inner, c->input_vrs, c->derived);
        status = cleared > status ? cleared : status;
    }
    return AFTER(c, status); /* fmi3Discard: still in step mode at the same time, the slave's state unchanged */
}

/* ------------------------------------------------------------------ what this FMU does not provide */

/* Refused in every state, with the reason (the capability that is declared false). */
#define UNSUPPORTED(call, reason, ...)                                                                      \
    fmi3Status call(fmi3Instance instance, ##__VA_ARGS__)                                                   \
    {                                                                                                       \
        ENTER(call, ANY_STATE)                                                                              \
        return REFUSE(c, "%s is not supported: %s", #call, reason);                                        \
    }

#define NO_EVENTS "this FMU has no event mode and no clocks (hasEventMode = false)"
#define NO_STRUCTURAL "this FMU has no structural parameters (array sizes are fixed when it is built)"

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference valueReference,
                                               size_t *nDependencies)
{
    (void)valueReference; (void)nDependencies;
    ENTER(fmi3GetNumberOfVariableDependencies, ANY_STATE)
    return REFUSE(c, "fmi3GetNumberOfVariableDependencies is not supported (providesPerElementDependencies = false): "
                  "see the dependencies in modelDescription.xml");
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[], fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies)
{
    (void)dependent; (void)elementIndicesOfDependent; (void)independents; (void)elementIndicesOfIndependents;
    (void)dependencyKinds; (void)nDependencies;
    ENTER(fmi3GetVariableDependencies, ANY_STATE)
    return REFUSE(c, "fmi3GetVariableDependencies is not supported (providesPerElementDependencies = false): "
                  "see the dependencies in modelDescription.xml");
}

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                        size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity)
{
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed; (void)sensitivity;
    (void)nSensitivity;
    ENTER(fmi3GetDirectionalDerivative, ANY_STATE)
    return REFUSE(c, "fmi3GetDirectionalDerivative is not supported (providesDirectionalDerivatives = false)");
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                    size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity)
{
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed; (void)sensitivity;
    (void)nSensitivity;
    ENTER(fmi3GetAdjointDerivative, ANY_STATE)
    return REFUSE(c, "fmi3GetAdjointDerivative is not supported (providesAdjointDerivatives = false)");
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                    size_t nValueReferences, const fmi3Int32 orders[], fmi3Float64 values[],
                                    size_t nValues)
{
    (void)valueReferences; (void)nValueReferences; (void)orders; (void)values; (void)nValues;
    ENTER(fmi3GetOutputDerivatives, ANY_STATE)
    return REFUSE(c, "fmi3GetOutputDerivatives is not supported (maxOutputDerivativeOrder = 0)");
}

UNSUPPORTED(fmi3EnterConfigurationMode, NO_STRUCTURAL)
UNSUPPORTED(fmi3ExitConfigurationMode, NO_STRUCTURAL)
UNSUPPORTED(fmi3EnterEventMode, NO_EVENTS)
UNSUPPORTED(fmi3EnterStepMode, "step mode is entered by fmi3ExitInitializationMode (hasEventMode = false)")
UNSUPPORTED(fmi3EvaluateDiscreteStates, "providesEvaluateDiscreteStates = false")
UNSUPPORTED(fmi3UpdateDiscreteStates, NO_EVENTS, fmi3Boolean *discreteStatesNeedUpdate,
            fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
            fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
            fmi3Float64 *nextEventTime)
UNSUPPORTED(fmi3GetClock, NO_EVENTS, const fmi3ValueReference valueReferences[], size_t nValueReferences,
            fmi3Clock values[])
UNSUPPORTED(fmi3SetClock, NO_EVENTS, const fmi3ValueReference valueReferences[], size_t nValueReferences,
            const fmi3Clock values[])
UNSUPPORTED(fmi3GetIntervalDecimal, NO_EVENTS, const fmi3ValueReference valueReferences[], size_t nValueReferences,
            fmi3Float64 intervals[], fmi3IntervalQualifier qualifiers[])
UNSUPPORTED(fmi3GetIntervalFraction, NO_EVENTS, const fmi3ValueReference valueReferences[], size_t nValueReferences,
            fmi3UInt64 counters[], fmi3UInt64 resolutions[], fmi3IntervalQualifier qualifiers[])
UNSUPPORTED(fmi3GetShiftDecimal, NO_EVENTS, const fmi3ValueReference valueReferences[], size_t nValueReferences,
            fmi3Float64 shifts[])
UNSUPPORTED(fmi3GetShiftFraction, NO_EVENTS, const fmi3ValueReference valueReferences[], size_t nValueReferences,
            fmi3UInt64 counters[], fmi3UInt64 resolutions[])
UNSUPPORTED(fmi3SetIntervalDecimal, NO_EVENTS, const fmi3ValueReference valueReferences[], size_t nValueReferences,
            const fmi3Float64 intervals[])
UNSUPPORTED(fmi3SetIntervalFraction, NO_EVENTS, const fmi3ValueReference valueReferences[], size_t nValueReferences,
            const fmi3UInt64 counters[], const fmi3UInt64 resolutions[])
UNSUPPORTED(fmi3SetShiftDecimal, NO_EVENTS, const fmi3ValueReference valueReferences[], size_t nValueReferences,
            const fmi3Float64 shifts[])
UNSUPPORTED(fmi3SetShiftFraction, NO_EVENTS, const fmi3ValueReference valueReferences[], size_t nValueReferences,
            const fmi3UInt64 counters[], const fmi3UInt64 resolutions[])
UNSUPPORTED(fmi3ActivateModelPartition, "scheduled execution is not supported", fmi3ValueReference clockReference,
            fmi3Float64 activationTime)

#define MODEL_EXCHANGE "this is a co-simulation FMU (no model exchange)"
UNSUPPORTED(fmi3EnterContinuousTimeMode, MODEL_EXCHANGE)
UNSUPPORTED(fmi3CompletedIntegratorStep, MODEL_EXCHANGE, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
            fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation)
UNSUPPORTED(fmi3SetTime, MODEL_EXCHANGE, fmi3Float64 time)
UNSUPPORTED(fmi3SetContinuousStates, MODEL_EXCHANGE, const fmi3Float64 continuousStates[], size_t nContinuousStates)
UNSUPPORTED(fmi3GetContinuousStateDerivatives, MODEL_EXCHANGE, fmi3Float64 derivatives[], size_t nContinuousStates)
UNSUPPORTED(fmi3GetEventIndicators, MODEL_EXCHANGE, fmi3Float64 eventIndicators[], size_t nEventIndicators)
UNSUPPORTED(fmi3GetContinuousStates, MODEL_EXCHANGE, fmi3Float64 continuousStates[], size_t nContinuousStates)
UNSUPPORTED(fmi3GetNominalsOfContinuousStates, MODEL_EXCHANGE, fmi3Float64 nominals[], size_t nContinuousStates)
UNSUPPORTED(fmi3GetNumberOfEventIndicators, MODEL_EXCHANGE, size_t *nEventIndicators)
UNSUPPORTED(fmi3GetNumberOfContinuousStates, MODEL_EXCHANGE, size_t *nContinuousStates)
