/*
 * The FMI 2.0 LOADER: binaries/<platform>/<model>.so of every obsfmu FMI 2.0 FMU (details:
 * docs/portability.md; the FMI 3.0 loader is loader_fmi3.c, what both share loader_common.h).
 *
 * Plain C, compiled without Python headers: it dlopens cleanly (RTLD_NOW) in any process.
 *   1. It enforces the FMI 2.0 co-simulation state machine (the standard's table of allowed
 *      calls per state, section 4.2.4) and checks the arguments of fmi2DoStep and
 *      fmi2SetRealInputDerivatives.  A call it refuses returns fmi2Error, logs the call and the
 *      reason, and changes nothing.  So does a call the slave refuses (fmi2Error, nothing changed:
 *      bad FMU-state bytes, a parameter after initialization, ...).  A call that FAILS inside the
 *      slave (fmi2Error: an unexpected exception, an error the slave logged) puts the instance in
 *      the error state, left only by fmi2SetFMUstate, fmi2Reset or fmi2FreeInstance.  fmi2Discard
 *      from fmi2DoStep leads to stepFailed (the standard's): fmi2SetFMUstate or fmi2Reset go on.
 *   2. At the first instantiation it gets Python: the interpreter already running in the process
 *      (fmpy, libcosimpy, ...: same major.minor version as the bridge required), or else
 *      libpython of $OBSFMU_PYTHON (a Python prefix, a virtual environment or a python executable)
 *      or of the Python recorded at build time, loaded RTLD_GLOBAL and started once per process,
 *      never finalized (loader_common.h).
 *   3. It loads the BRIDGE (bridge.c, RTLD_LOCAL) and forwards every call to its function table.
 */
#define _GNU_SOURCE /* dl_iterate_phdr */
#include "fmi2Functions.h"
#include "loader_common.h"

/* ------------------------------------------------------------------ state machine */

/* stepInProgress and stepCanceled never occur: steps are synchronous (canRunAsynchronuously = false). */
enum {
    INSTANTIATED = 1,
    INITIALIZATION_MODE = 2,
    STEP_COMPLETE = 4,
    STEP_FAILED = 8,
    TERMINATED = 16,
    ERROR = 32,
};

#define ANY_STATE (INSTANTIATED | INITIALIZATION_MODE | STEP_COMPLETE | STEP_FAILED | TERMINATED | ERROR)
#define SETTABLE (INSTANTIATED | INITIALIZATION_MODE | STEP_COMPLETE)
#define READABLE (INITIALIZATION_MODE | STEP_COMPLETE | STEP_FAILED | TERMINATED | ERROR)
#define STEPPED (STEP_COMPLETE | STEP_FAILED | TERMINATED | ERROR)
#define STATUS_QUERY (STEP_COMPLETE | STEP_FAILED | TERMINATED)
#define NO_STATE 0

static const char *state_name(unsigned state)
{
    switch (state) {
    case INSTANTIATED: return "instantiated";
    case INITIALIZATION_MODE: return "initializationMode";
    case STEP_COMPLETE: return "stepComplete";
    case STEP_FAILED: return "stepFailed";
    case TERMINATED: return "terminated";
    default: return "error";
    }
}

static const Version FMI2 = {2, ANY_STATE, INSTANTIATED | INITIALIZATION_MODE, STEP_COMPLETE | STEP_FAILED | TERMINATED,
                             ERROR, state_name, "fmi2"};

typedef Core Instance;

/* The instance, or fmi2Error when it is not one this FMU issued and has not freed (no logger is known
 * then: nothing is logged), or when the call is not allowed in its state (nothing changes). */
#define ENTER(call, allowed)                                                                      \
    Instance *c = (Instance *)component;                                                          \
    if (!handle_known(&instances, c)) return fmi2Error;                                           \
    if (!(c->state & (allowed))) return refuse(c, "%s is not allowed in state %s", #call, state_name(c->state));

/* ------------------------------------------------------------------ FMI API */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn)
{
    const char *name = instanceName ? instanceName : "";
    char message[8192];
    if (fmuType != fmi2CoSimulation) {
        say(functions, name, fmi2Error, "fmi2Instantiate: this FMU supports co-simulation only");
        return NULL;
    }
    if (fmuResourceLocation == NULL) {
        say(functions, name, fmi2Error, "fmi2Instantiate: fmuResourceLocation is required");
        return NULL;
    }
    char *resources = obsfmu_resource_path(fmuResourceLocation);
    char *record = checked_record(functions, name, "fmi2Instantiate", resources, fmuResourceLocation, fmuGUID, "GUID");
    Instance *c = NULL;
    if (record == NULL) goto done;
    const ObsfmuBridge *functions_of_bridge = get_bridge(resources, record, message, sizeof message);
    if (functions_of_bridge == NULL) {
        say(functions, name, fmi2Error, "fmi2Instantiate: %s", message);
        goto done;
    }
    fmi2Component inner = functions_of_bridge->instantiate(instanceName, fmuType, fmuGUID, fmuResourceLocation,
                                                           functions, visible, loggingOn);
    if (inner == NULL) goto done; /* the bridge logged why */
    c = calloc(1, sizeof(Instance));
    if (c != NULL && functions) c->callbacks = *functions;
    if (c == NULL || core_init(c, &FMI2, functions_of_bridge, inner, name, INSTANTIATED, resources) != 0
        || handle_add(&instances, c, NULL) != 0) {
        functions_of_bridge->freeInstance(inner);
        if (c) core_free(c);
        free(c);
        c = NULL;
        goto done;
    }
done:
    free(record);
    free(resources);
    return c;
}

void fmi2FreeInstance(fmi2Component component)
{
    Instance *c = (Instance *)component;
    if (!handle_remove(&instances, c)) return; /* NULL, not this FMU's, or freed already: nothing to do */
    core_free_states(c);
    c->bridge->freeInstance(c->inner);
    core_free(c);
    free(c);
}

fmi2Status fmi2SetDebugLogging(fmi2Component component, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[])
{
    ENTER(fmi2SetDebugLogging, ANY_STATE)
    return after(c, c->bridge->setDebugLogging(c->inner, loggingOn, nCategories, categories));
}

fmi2Status fmi2SetupExperiment(fmi2Component component, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    ENTER(fmi2SetupExperiment, INSTANTIATED)
    if (!finite(startTime)) return refuse(c, "fmi2SetupExperiment: startTime %g is not finite", startTime);
    fmi2Status status = c->bridge->setupExperiment(c->inner, toleranceDefined, tolerance, startTime,
                                                   stopTimeDefined, stopTime);
    if (status < fmi2Error) c->time = startTime;
    return after(c, status);
}

fmi2Status fmi2EnterInitializationMode(fmi2Component component)
{
    ENTER(fmi2EnterInitializationMode, INSTANTIATED)
    fmi2Status status = c->bridge->enterInitializationMode(c->inner);
    if (status < fmi2Error) c->state = INITIALIZATION_MODE;
    return after(c, status);
}

fmi2Status fmi2ExitInitializationMode(fmi2Component component)
{
    ENTER(fmi2ExitInitializationMode, INITIALIZATION_MODE)
    fmi2Status status = c->bridge->exitInitializationMode(c->inner);
    if (status < fmi2Error) c->state = STEP_COMPLETE;
    return after(c, status);
}

fmi2Status fmi2Terminate(fmi2Component component)
{
    ENTER(fmi2Terminate, STEP_COMPLETE | STEP_FAILED)
    fmi2Status status = c->bridge->terminate(c->inner);
    if (status < fmi2Error) c->state = TERMINATED;
    return after(c, status);
}

fmi2Status fmi2Reset(fmi2Component component)
{
    ENTER(fmi2Reset, ANY_STATE)
    return core_reset(c, INSTANTIATED);
}

/* ---- values */

/* `name`: the entry point, a string.  More values than the FMU has variables is refused before the
 * arrays are read (an nvr of 2^40 would otherwise reach the slave as a list of that size). */
#define ARRAYS(name, vr, nvr, value)                                                                   \
    if ((nvr) > c->variable_count)                                                                     \
        return refuse(c, "%s: nvr %zu larger than the FMU's variables (%zu)", name, (size_t)(nvr),      \
                      c->variable_count);                                                              \
    if ((nvr) > 0 && ((vr) == NULL || (value) == NULL))                                                \
        return refuse(c, "%s: NULL value references or values for %zu variables", name, (size_t)(nvr));

#define GETTER(call, member, type)                                                                     \
    fmi2Status call(fmi2Component component, const fmi2ValueReference vr[], size_t nvr, type value[])  \
    {                                                                                                  \
        ENTER(call, READABLE)                                                                          \
        ARRAYS(#call, vr, nvr, value)                                                                  \
        return after(c, c->bridge->member(c->inner, vr, nvr, value));                                 \
    }

#define SETTER(call, member, type)                                                                     \
    fmi2Status call(fmi2Component component, const fmi2ValueReference vr[], size_t nvr, const type value[]) \
    {                                                                                                  \
        ENTER(call, SETTABLE)                                                                          \
        ARRAYS(#call, vr, nvr, value)                                                                  \
        return after(c, c->bridge->member(c->inner, vr, nvr, value));                                 \
    }

GETTER(fmi2GetReal, getReal, fmi2Real)
GETTER(fmi2GetInteger, getInteger, fmi2Integer)
GETTER(fmi2GetBoolean, getBoolean, fmi2Boolean)
GETTER(fmi2GetString, getString, fmi2String)
SETTER(fmi2SetReal, setReal, fmi2Real)
SETTER(fmi2SetInteger, setInteger, fmi2Integer)
SETTER(fmi2SetBoolean, setBoolean, fmi2Boolean)
SETTER(fmi2SetString, setString, fmi2String)

/* ---- FMU state: the slave's, holding the state machine's state (loader_common.h) */

fmi2Status fmi2GetFMUstate(fmi2Component component, fmi2FMUstate *state)
{
    ENTER(fmi2GetFMUstate, ANY_STATE)
    return core_get_state(c, "fmi2GetFMUstate", state);
}

fmi2Status fmi2SetFMUstate(fmi2Component component, fmi2FMUstate state)
{
    ENTER(fmi2SetFMUstate, ANY_STATE)
    return core_set_state(c, "fmi2SetFMUstate", state);
}

fmi2Status fmi2FreeFMUstate(fmi2Component component, fmi2FMUstate *state)
{
    ENTER(fmi2FreeFMUstate, ANY_STATE)
    return core_free_state(c, "fmi2FreeFMUstate", state);
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component component, fmi2FMUstate state, size_t *size)
{
    ENTER(fmi2SerializedFMUstateSize, ANY_STATE)
    return core_serialized_size(c, "fmi2SerializedFMUstateSize", state, size);
}

fmi2Status fmi2SerializeFMUstate(fmi2Component component, fmi2FMUstate state, fmi2Byte buffer[], size_t size)
{
    ENTER(fmi2SerializeFMUstate, ANY_STATE)
    return core_serialize(c, "fmi2SerializeFMUstate", state, buffer, size);
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component component, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *state)
{
    ENTER(fmi2DeSerializeFMUstate, ANY_STATE)
    return core_deserialize(c, "fmi2DeSerializeFMUstate", serializedState, size, state);
}

/* ---- derivatives */

fmi2Status fmi2GetDirectionalDerivative(fmi2Component component, const fmi2ValueReference vUnknown_ref[],
                                        size_t nUnknown, const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[])
{
    (void)vUnknown_ref; (void)nUnknown; (void)vKnown_ref; (void)nKnown; (void)dvKnown; (void)dvUnknown;
    ENTER(fmi2GetDirectionalDerivative, READABLE)
    return refuse(c, "fmi2GetDirectionalDerivative is not supported (providesDirectionalDerivative = false)");
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component component, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[])
{
    ENTER(fmi2SetRealInputDerivatives, SETTABLE)
    ARRAYS("fmi2SetRealInputDerivatives", vr, nvr, value)
    for (size_t i = 0; i < nvr; i++) {
        if (order == NULL || order[i] != 1)
            return refuse(c, "fmi2SetRealInputDerivatives: derivative of order %d for value reference %u: only "
                          "first derivatives (order 1) are used", order ? order[i] : 0, vr[i]);
    }
    return after(c, c->bridge->setRealInputDerivatives(c->inner, vr, nvr, order, value));
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component component, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[])
{
    ENTER(fmi2GetRealOutputDerivatives, STEPPED)
    ARRAYS("fmi2GetRealOutputDerivatives", vr, nvr, value)
    ARRAYS("fmi2GetRealOutputDerivatives", vr, nvr, order)
    /* the slave refuses an FMU without them (maxOutputDerivativeOrder = 0), an order other than 1, a non-output */
    return after(c, c->bridge->getRealOutputDerivatives(c->inner, vr, nvr, order, value));
}

/* ---- stepping */

fmi2Status fmi2DoStep(fmi2Component component, fmi2Real currentCommunicationPoint,
                      fmi2Real communicationStepSize, fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    ENTER(fmi2DoStep, STEP_COMPLETE)
    double t = currentCommunicationPoint, h = communicationStepSize;
    if (check_step(c, "fmi2DoStep", t, h) != fmi2OK) return fmi2Error;
    fmi2Status status = c->bridge->doStep(c->inner, t, h, noSetFMUStatePriorToCurrentPoint);
    if (status <= fmi2Warning) c->time = t + h;
    else if (status == fmi2Discard) c->state = STEP_FAILED;
    return after(c, status);
}

/* The one-call step of an instance whose state allows it, with fmi2DoStep's checks and transitions;
 * `call` names the entry point in messages. */
static fmi2Status batched_step(Instance *c, const char *call, fmi2Real t, fmi2Real h, const fmi2ValueReference vr[],
                               size_t nvr, const fmi2Real value[], const fmi2Real slope[],
                               const fmi2ValueReference outputVr[], size_t nOutputs, fmi2Real output[])
{
    ARRAYS(call, vr, nvr, value)
    ARRAYS(call, outputVr, nOutputs, output)
    if (check_step(c, call, t, h) != fmi2OK) return fmi2Error;
    int stepped = 0;
    fmi2Status status = c->bridge->doStepBatched(c->inner, t, h, vr, nvr, value, slope, outputVr, nOutputs, output,
                                                 &stepped);
    if (stepped) c->time = t + h;
    else if (status == fmi2Discard) c->state = STEP_FAILED;
    return after(c, status);
}

/* obsfmu's extension for its own master (not part of FMI 2.0; docs/portability.md): one communication
 * step in one call, exactly
 *     fmi2SetReal(vr, value); [fmi2SetRealInputDerivatives(vr, 1, slope) unless slope == NULL;]
 *     fmi2DoStep(t, h, fmi2True); fmi2GetReal(outputVr, output)
 * with the same checks, statuses and state machine, in one call of the bridge (one Python call instead
 * of four).  Allowed where fmi2DoStep is; `output` is written only if the step was taken. */
OBSFMU_EXPORT fmi2Status obsfmuDoStepBatched(
    fmi2Component component, fmi2Real t, fmi2Real h, const fmi2ValueReference vr[], size_t nvr,
    const fmi2Real value[], const fmi2Real slope[], const fmi2ValueReference outputVr[], size_t nOutputs,
    fmi2Real output[])
{
    ENTER(obsfmuDoStepBatched, STEP_COMPLETE)
    return batched_step(c, "obsfmuDoStepBatched", t, h, vr, nvr, value, slope, outputVr, nOutputs, output);
}

/* The arguments of obsfmuDoStepBatched after t and h, in one struct the caller builds once. */
typedef struct {
    const fmi2ValueReference *vr;
    size_t nvr;
    const fmi2Real *value;
    const fmi2Real *slope; /* NULL: no derivatives */
    const fmi2ValueReference *outputVr;
    size_t nOutputs;
    fmi2Real *output;
} ObsfmuStepPlan;

/* obsfmuDoStepBatched with its arrays in a plan: four arguments instead of ten, which is what a
 * caller through an FFI pays for per step (Python's ctypes: ~0.05 us per argument). */
OBSFMU_EXPORT fmi2Status obsfmuDoStepPlanned(
    fmi2Component component, fmi2Real t, fmi2Real h, const ObsfmuStepPlan *plan)
{
    ENTER(obsfmuDoStepPlanned, STEP_COMPLETE)
    if (plan == NULL) return refuse(c, "obsfmuDoStepPlanned: NULL plan");
    return batched_step(c, "obsfmuDoStepPlanned", t, h, plan->vr, plan->nvr, plan->value, plan->slope, plan->outputVr,
                        plan->nOutputs, plan->output);
}

/* One FMU of a co-simulation round (obsfmuRound): an instance of any obsfmu FMI 2.0 binary. */
typedef struct {
    fmi2Status (*step)(fmi2Component, fmi2Real, fmi2Real, const ObsfmuStepPlan *); /* its obsfmuDoStepPlanned */
    fmi2Component component;
    const ObsfmuStepPlan *plan;    /* its value and slope vectors are filled here; it writes its outputs into live */
    const size_t *source;          /* per input of the plan: the output it is connected to (index in live) */
    const unsigned char *stepped;  /* per input: that output's FMU steps earlier in the round */
} ObsfmuRoundMember;

/* The project master's Gauss-Seidel round (fmus/master.py, _Stepper.round), built once per run. */
typedef struct {
    size_t nMembers;
    const ObsfmuRoundMember *member;  /* in the order they step */
    size_t nOutputs;
    const fmi2Real *live;   /* every output, as the members' steps leave them */
    fmi2Real *now;          /* the outputs at the communication point t (written: those at t + h) */
    fmi2Real *before;       /* those at the point before (written: those at t) */
    fmi2Real *slope;        /* room for nOutputs slopes */
    fmi2Real hBefore;       /* the step from `before` to `now`; 0: no history (written: h) */
    int linear;             /* 1: inputs follow first-order extrapolation/interpolation; 0: held */
} ObsfmuRound;

/* obsfmu's extension for its own master (not part of FMI 2.0; docs/portability.md): one communication
 * round of several obsfmu FMUs in one call.  Member by member: its inputs from the outputs (`now` when
 * linear, else `live`), with linear coupling their slopes -- interpolated from t to t + h for an output
 * stepped earlier in this round, (now - before) / hBefore otherwise -- then its obsfmuDoStepPlanned.
 * The first status worse than fmi2Warning ends the round: it is returned and *failed names the member.
 * A round that completes moves the history on (before <- now <- live, hBefore <- h).  This is exactly
 * what the master's Python round computes, operation for operation (the tests compare bit for bit). */
OBSFMU_EXPORT fmi2Status obsfmuRound(ObsfmuRound *round, fmi2Real t, fmi2Real h,
                                                              size_t *failed)
{
    if (round == NULL || failed == NULL || !(h > 0.0)) return fmi2Error;
    *failed = round->nMembers;
    const size_t n = round->nOutputs;
    const fmi2Real *live = round->live, *now = round->now, *before = round->before;
    fmi2Real *slope = round->slope;
    for (size_t k = 0; k < round->nMembers; k++) {           /* every link within the outputs */
        const ObsfmuRoundMember *m = &round->member[k];
        if (m->step == NULL || m->plan == NULL || (m->plan->nvr > 0 && (m->source == NULL || m->stepped == NULL))) {
            *failed = k;
            return fmi2Error;
        }
        for (size_t i = 0; i < m->plan->nvr; i++)
            if (m->source[i] >= n) { *failed = k; return fmi2Error; }
    }
    if (round->linear)
        for (size_t i = 0; i < n; i++) slope[i] = round->hBefore > 0.0 ? (now[i] - before[i]) / round->hBefore : 0.0;
    const fmi2Real *source = round->linear ? now : live;
    fmi2Status worst = fmi2OK;
    for (size_t k = 0; k < round->nMembers; k++) {
        const ObsfmuRoundMember *m = &round->member[k];
        fmi2Real *value = (fmi2Real *)m->plan->value, *value_slope = (fmi2Real *)m->plan->slope;
        for (size_t i = 0; i < m->plan->nvr; i++) {
            const size_t s = m->source[i];
            value[i] = source[s];
            if (value_slope != NULL)
                value_slope[i] = !round->linear ? 0.0 : m->stepped[i] ? (live[s] - value[i]) / h : slope[s];
        }
        fmi2Status status = m->step(m->component, t, h, m->plan);
        if (status > fmi2Warning) {
            *failed = k;
            return status;
        }
        if (status > worst) worst = status;
    }
    memcpy(round->before, now, n * sizeof(fmi2Real));
    memcpy(round->now, live, n * sizeof(fmi2Real));
    round->hBefore = h;
    return worst;
}

fmi2Status fmi2CancelStep(fmi2Component component)
{
    ENTER(fmi2CancelStep, NO_STATE) /* steps are synchronous: never in stepInProgress */
    return fmi2Error;
}

fmi2Status fmi2GetStatus(fmi2Component component, const fmi2StatusKind s, fmi2Status *value)
{
    (void)s; (void)value;
    ENTER(fmi2GetStatus, STATUS_QUERY)
    return fmi2Discard; /* fmi2DoStepStatus: only meaningful after fmi2Pending, which never happens */
}

fmi2Status fmi2GetRealStatus(fmi2Component component, const fmi2StatusKind s, fmi2Real *value)
{
    ENTER(fmi2GetRealStatus, STATUS_QUERY)
    if (s != fmi2LastSuccessfulTime || value == NULL) return fmi2Discard;
    *value = c->time;
    return fmi2OK;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component component, const fmi2StatusKind s, fmi2Integer *value)
{
    (void)s; (void)value;
    ENTER(fmi2GetIntegerStatus, STATUS_QUERY)
    return fmi2Discard;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component component, const fmi2StatusKind s, fmi2Boolean *value)
{
    ENTER(fmi2GetBooleanStatus, STATUS_QUERY)
    if (s != fmi2Terminated || value == NULL) return fmi2Discard;
    *value = fmi2False; /* the slave never asks to end the simulation */
    return fmi2OK;
}

fmi2Status fmi2GetStringStatus(fmi2Component component, const fmi2StatusKind s, fmi2String *value)
{
    (void)s; (void)value;
    ENTER(fmi2GetStringStatus, STATUS_QUERY)
    return fmi2Discard;
}
