/*
 * The LOADER: binaries/<platform>/<model>.so of every obsfmu FMU (details: docs/portability.md).
 *
 * Plain C, compiled without Python headers: it dlopens cleanly (RTLD_NOW) in any process.
 *   1. It enforces the FMI 2.0 co-simulation state machine (the standard's table of allowed
 *      calls per state, section 4.2.4) and checks the arguments of fmi2DoStep and
 *      fmi2SetRealInputDerivatives.  A call it refuses returns fmi2Error, logs the call and the
 *      reason, and changes nothing.  A failure inside the slave (fmi2Error) puts the instance in
 *      the error state, left only by fmi2SetFMUstate, fmi2Reset or fmi2FreeInstance.
 *   2. At the first instantiation it gets Python: the interpreter already running in the process
 *      (fmpy, libcosimpy, ...: same major.minor version as the bridge required), or else
 *      libpython of $OBSFMU_PYTHON (a Python prefix, a virtual environment or a python executable)
 *      or of the Python recorded at build time, loaded RTLD_GLOBAL and started once per process,
 *      never finalized.
 *   3. It loads the BRIDGE (bridge.c, RTLD_LOCAL) and forwards every call to its function table.
 */
#include <dlfcn.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdint.h>
#include <sys/stat.h>

#include "fmi2Functions.h"
#include "obsfmu_native.h"

#define OVERRIDE "OBSFMU_PYTHON"
#define PATH_SIZE 4096

/* ------------------------------------------------------------------ state machine */

/* stepInProgress and stepCanceled never occur: steps are synchronous (canRunAsynchronuously = false). */
typedef enum {
    INSTANTIATED = 1,
    INITIALIZATION_MODE = 2,
    STEP_COMPLETE = 4,
    STEP_FAILED = 8,
    TERMINATED = 16,
    ERROR = 32,
} State;

#define ANY_STATE (INSTANTIATED | INITIALIZATION_MODE | STEP_COMPLETE | STEP_FAILED | TERMINATED | ERROR)
#define SETTABLE (INSTANTIATED | INITIALIZATION_MODE | STEP_COMPLETE)
#define READABLE (INITIALIZATION_MODE | STEP_COMPLETE | STEP_FAILED | TERMINATED | ERROR)
#define STEPPED (STEP_COMPLETE | STEP_FAILED | TERMINATED | ERROR)
#define STATUS_QUERY (STEP_COMPLETE | STEP_FAILED | TERMINATED)
#define NO_STATE 0

static const char *state_name(State state)
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

typedef struct {
    const ObsfmuBridge *bridge;
    fmi2Component inner;
    State state;
    double time; /* the FMU's current communication point */
    fmi2CallbackFunctions callbacks;
    char *name;
} Instance;

/* An FMU state: the slave's plus the state machine's. */
typedef struct {
    fmi2FMUstate inner;
    State state;
    double time;
} Snapshot;

static void say(const fmi2CallbackFunctions *callbacks, const char *name, fmi2Status status, const char *format, ...)
{
    char message[8192];
    va_list arguments;
    va_start(arguments, format);
    vsnprintf(message, sizeof message, format, arguments);
    va_end(arguments);
    obsfmu_emit(callbacks, name, status, obsfmu_category(status), message);
}

#define refuse(c, ...) (say(&(c)->callbacks, (c)->name, fmi2Error, __VA_ARGS__), fmi2Error)

/* The instance, or fmi2Error when the call is not allowed in its state (nothing changes). */
#define ENTER(call, allowed)                                                                      \
    Instance *c = (Instance *)component;                                                          \
    if (c == NULL) return fmi2Error;                                                              \
    if (!(c->state & (allowed))) return refuse(c, "%s is not allowed in state %s", #call, state_name(c->state));

/* A slave failure leaves the instance in the error state. */
static fmi2Status after(Instance *c, fmi2Status status)
{
    if (status < fmi2Error) return status;
    c->state = ERROR;
    return fmi2Error;
}

static double magnitude(double x) { return x < 0 ? -x : x; }
static int finite(double x) { return x == x && magnitude(x) <= 1.7976931348623157e308; }

/* ------------------------------------------------------------------ finding Python */

static pthread_mutex_t lock = PTHREAD_MUTEX_INITIALIZER;
static void *bridge_library;          /* this loader's bridge (closed when the loader is unloaded) */
static const ObsfmuBridge *bridge;
static char start_failure[PATH_SIZE]; /* an interpreter that failed to start cannot be retried */

static int exists(const char *path)
{
    struct stat info;
    return path[0] != '\0' && stat(path, &info) == 0;
}

/* "3.11.7 (main, ...)" has the version "3.11" (and "3.1" does not). */
static int same_version(const char *running, const char *wanted)
{
    size_t n = strlen(wanted);
    return running && strncmp(running, wanted, n) == 0 && (running[n] == '.' || running[n] == ' ' || running[n] == '\0');
}

/* dirname, in place */
static void parent(char *path)
{
    char *slash = strrchr(path, '/');
    if (slash && slash != path) *slash = '\0';
    else if (slash) slash[1] = '\0';
}

/* Append `path` to the list of places looked at; return it if it exists. */
static int candidate(const char *path, char *tried, size_t size)
{
    size_t used = strlen(tried);
    snprintf(tried + used, size - used, "%s%s", used ? ", " : "", path);
    return exists(path);
}

/* <root>/pyvenv.cfg (a virtual environment) says "home = <base>/bin"; otherwise base = root. */
static void base_installation(const char *root, char *base, size_t size)
{
    char path[PATH_SIZE], line[PATH_SIZE];
    snprintf(base, size, "%s", root);
    snprintf(path, sizeof path, "%s/pyvenv.cfg", root);
    FILE *file = fopen(path, "r");
    if (file == NULL) return;
    while (fgets(line, sizeof line, file)) {
        char *value = strchr(line, '=');
        if (strncmp(line, "home", 4) != 0 || strchr(" \t=", line[4]) == NULL || value == NULL) continue;
        value += 1 + strspn(value + 1, " \t");
        value[strcspn(value, "\r\n")] = '\0';
        snprintf(base, size, "%s", value);
        parent(base);
    }
    fclose(file);
}

/* The python executable and libpython of $OBSFMU_PYTHON: a prefix, a venv or a python executable. */
static int python_from_override(const char *value, const char *record, char *program, char *library,
                                char *tried, size_t size)
{
    char version[32], multiarch[128], root[PATH_SIZE], base[PATH_SIZE], path[2 * PATH_SIZE + 64];
    obsfmu_record_value(record, "python_version", version, sizeof version);
    obsfmu_record_value(record, "python_multiarch", multiarch, sizeof multiarch);
    struct stat info;
    program[0] = library[0] = '\0';
    snprintf(root, sizeof root, "%s", value);
    if (stat(value, &info) == 0 && !S_ISDIR(info.st_mode)) { /* <root>/bin/python */
        snprintf(program, PATH_SIZE, "%s", value);
        parent(root);
        parent(root);
    } else {
        const char *names[] = {version, "3", ""};
        for (int i = 0; i < 3 && !program[0]; i++) {
            snprintf(path, sizeof path, "%s/bin/python%s", root, names[i]);
            if (candidate(path, tried, size)) snprintf(program, PATH_SIZE, "%s", path);
        }
    }
    base_installation(root, base, sizeof base);
    char folders[3][160] = {"lib", "lib64", ""};
    if (multiarch[0]) snprintf(folders[2], sizeof folders[2], "lib/%s", multiarch);
    const char *suffixes[] = {".so.1.0", ".so.1", ".so"};
    for (int f = 0; f < 3 && !library[0]; f++) {
        for (int s = 0; folders[f][0] && s < 3 && !library[0]; s++) {
            snprintf(path, sizeof path, "%s/%s/libpython%s%s", base, folders[f], version, suffixes[s]);
            if (candidate(path, tried, size)) snprintf(library, PATH_SIZE, "%s", path);
        }
    }
    return program[0] && library[0];
}

/* Load libpython (RTLD_GLOBAL: extension modules resolve their symbols there); 1 if it must be started. */
static void *load_python(const char *record, char *program, int *must_start, char *message, size_t size)
{
    char version[32], library[PATH_SIZE], tried[PATH_SIZE] = "";
    obsfmu_record_value(record, "python_version", version, sizeof version);
    const char *override = getenv(OVERRIDE);
    const char *fix = "set " OVERRIDE " to a Python %s installation prefix, virtual environment or python "
                      "executable that has numpy and scipy (e.g. " OVERRIDE "=/path/to/venv)";
    char hint[512];
    snprintf(hint, sizeof hint, fix, version);
    if (override && override[0]) {
        if (!python_from_override(override, record, program, library, tried, sizeof tried)) {
            snprintf(message, size, "no usable Python %s for this FMU: no Python runs in this process, and "
                     OVERRIDE "=%s has no python executable and libpython%s (looked for %s); %s", version,
                     override, version, tried, hint);
            return NULL;
        }
    } else {
        obsfmu_record_value(record, "python_executable", program, PATH_SIZE);
        obsfmu_record_value(record, "python_library", library, sizeof library);
        if (!exists(program) || !exists(library)) {
            snprintf(message, size, "no usable Python %s for this FMU: no Python runs in this process, "
                     OVERRIDE " is not set, and the Python recorded when the FMU was built is not here "
                     "(python executable %s: %s; shared library libpython %s: %s); %s", version,
                     program[0] ? program : "(none)", exists(program) ? "found" : "missing",
                     library[0] ? library : "(none: that Python has no shared libpython)",
                     exists(library) ? "found" : "missing", hint);
            return NULL;
        }
    }
    void *python = dlopen(library, RTLD_NOW | RTLD_GLOBAL);
    if (python == NULL) {
        snprintf(message, size, "cannot load %s: %s; %s", library, dlerror(), hint);
        return NULL;
    }
    const char *(*get_version)(void) = (const char *(*)(void))dlsym(python, "Py_GetVersion");
    int (*initialized)(void) = (int (*)(void))dlsym(python, "Py_IsInitialized");
    if (get_version == NULL || initialized == NULL || !same_version(get_version(), version)) {
        snprintf(message, size, "%s is not Python %s (it is %.20s); %s", library, version,
                 get_version ? get_version() : "not a libpython", hint);
        return NULL; /* never dlclose a libpython: it may have run already */
    }
    *must_start = !initialized();
    return python;
}

/* The bridge of this FMU, with a Python to run it; NULL and a message saying what is missing. */
static const ObsfmuBridge *get_bridge(const char *resources, const char *record, char *message, size_t size)
{
    pthread_mutex_lock(&lock);
    if (bridge == NULL && start_failure[0]) snprintf(message, size, "%s", start_failure);
    if (bridge != NULL || start_failure[0]) goto done;

    char version[32], program[PATH_SIZE] = "", name[PATH_SIZE], path[2 * PATH_SIZE];
    obsfmu_record_value(record, "python_version", version, sizeof version);
    obsfmu_record_value(record, "bridge", name, sizeof name);
    int must_start = 0;
    int (*initialized)(void) = (int (*)(void))dlsym(RTLD_DEFAULT, "Py_IsInitialized");
    if (initialized != NULL) { /* the process has Python: use it */
        const char *(*get_version)(void) = (const char *(*)(void))dlsym(RTLD_DEFAULT, "Py_GetVersion");
        const char *running = get_version ? get_version() : "";
        if (!same_version(running, version)) {
            snprintf(message, size, "this process runs Python %.20s, but this FMU's binary was built for Python %s: "
                     "load it from a Python %s process, or rebuild it (obsfmu build) with the host's Python",
                     running, version, version);
            goto done;
        }
        must_start = !initialized();
        obsfmu_record_value(record, "python_executable", program, sizeof program);
    } else if (load_python(record, program, &must_start, message, size) == NULL) {
        goto done;
    }

    snprintf(path, sizeof path, "%s/../%s", resources, name);
    void *library = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    ObsfmuBridgeFunction *table = library ? (ObsfmuBridgeFunction *)dlsym(library, OBSFMU_BRIDGE_SYMBOL) : NULL;
    if (table == NULL || table()->abi != OBSFMU_BRIDGE_ABI) {
        snprintf(message, size, "cannot load the FMU's bridge %s: %s", path,
                 library ? "not an obsfmu bridge of this version" : dlerror());
        if (library) dlclose(library);
        goto done;
    }
    if (must_start && table()->start(program, message, size) != 0) {
        snprintf(start_failure, sizeof start_failure, "%s", message);
        goto done; /* the bridge stays loaded: the half-started interpreter may point into it */
    }
    bridge_library = library;
    bridge = table();
done:
    pthread_mutex_unlock(&lock);
    return bridge;
}

__attribute__((destructor)) static void unload(void)
{
    if (bridge_library) dlclose(bridge_library);
}

/* ------------------------------------------------------------------ FMI API */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn)
{
    const char *name = instanceName ? instanceName : "";
    char guid[128], message[8192];
    if (fmuType != fmi2CoSimulation) {
        say(functions, name, fmi2Error, "fmi2Instantiate: this FMU supports co-simulation only");
        return NULL;
    }
    if (fmuResourceLocation == NULL) {
        say(functions, name, fmi2Error, "fmi2Instantiate: fmuResourceLocation is required");
        return NULL;
    }
    char *resources = obsfmu_resource_path(fmuResourceLocation);
    char *record = resources ? obsfmu_read_record(resources) : NULL;
    Instance *c = NULL;
    if (record == NULL) {
        say(functions, name, fmi2Error, "fmi2Instantiate: cannot read %s/" OBSFMU_RECORD " (fmuResourceLocation %s):"
            " not an unzipped obsfmu FMU", resources ? resources : "", fmuResourceLocation);
        goto done;
    }
    obsfmu_record_value(record, "guid", guid, sizeof guid);
    if (fmuGUID == NULL || strcmp(fmuGUID, guid) != 0) {
        say(functions, name, fmi2Error, "fmi2Instantiate: GUID %s is not this FMU's (%s): the modelDescription.xml "
            "used does not belong to this binary", fmuGUID ? fmuGUID : "(null)", guid);
        goto done;
    }
    const ObsfmuBridge *functions_of_bridge = get_bridge(resources, record, message, sizeof message);
    if (functions_of_bridge == NULL) {
        say(functions, name, fmi2Error, "fmi2Instantiate: %s", message);
        goto done;
    }
    fmi2Component inner = functions_of_bridge->instantiate(instanceName, fmuType, fmuGUID, fmuResourceLocation,
                                                           functions, visible, loggingOn);
    if (inner == NULL) goto done; /* the bridge logged why */
    c = calloc(1, sizeof(Instance));
    char *copy = malloc(strlen(name) + 1);
    if (c == NULL || copy == NULL) {
        functions_of_bridge->freeInstance(inner);
        free(c);
        free(copy);
        c = NULL;
        goto done;
    }
    c->name = strcpy(copy, name);
    c->bridge = functions_of_bridge;
    c->inner = inner;
    c->state = INSTANTIATED;
    c->time = 0.0;
    if (functions) c->callbacks = *functions;
done:
    free(record);
    free(resources);
    return c;
}

void fmi2FreeInstance(fmi2Component component)
{
    Instance *c = (Instance *)component;
    if (c == NULL) return;
    c->bridge->freeInstance(c->inner);
    free(c->name);
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
    fmi2Status status = c->bridge->reset(c->inner);
    if (status < fmi2Error) {
        c->state = INSTANTIATED;
        c->time = 0.0;
    }
    return after(c, status);
}

/* ---- values */

#define ARRAYS(call, vr, nvr, value)                                                                   \
    if ((nvr) > 0 && ((vr) == NULL || (value) == NULL))                                                \
        return refuse(c, "%s: NULL value references or values for %zu variables", #call, (size_t)(nvr));

#define GETTER(call, member, type)                                                                     \
    fmi2Status call(fmi2Component component, const fmi2ValueReference vr[], size_t nvr, type value[])  \
    {                                                                                                  \
        ENTER(call, READABLE)                                                                          \
        ARRAYS(call, vr, nvr, value)                                                                   \
        return after(c, c->bridge->member(c->inner, vr, nvr, value));                                 \
    }

#define SETTER(call, member, type)                                                                     \
    fmi2Status call(fmi2Component component, const fmi2ValueReference vr[], size_t nvr, const type value[]) \
    {                                                                                                  \
        ENTER(call, SETTABLE)                                                                          \
        ARRAYS(call, vr, nvr, value)                                                                   \
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

/* ---- FMU state: the slave's state plus the state machine's (state, time) */

fmi2Status fmi2GetFMUstate(fmi2Component component, fmi2FMUstate *state)
{
    ENTER(fmi2GetFMUstate, ANY_STATE)
    if (state == NULL) return refuse(c, "fmi2GetFMUstate: FMUstate is NULL");
    Snapshot *snapshot = *state ? (Snapshot *)*state : calloc(1, sizeof(Snapshot));
    if (snapshot == NULL) return refuse(c, "fmi2GetFMUstate: out of memory");
    fmi2Status status = c->bridge->getFMUstate(c->inner, &snapshot->inner);
    if (status < fmi2Error) {
        snapshot->state = c->state;
        snapshot->time = c->time;
        *state = snapshot;
    } else if (*state == NULL) {
        free(snapshot);
    }
    return after(c, status);
}

fmi2Status fmi2SetFMUstate(fmi2Component component, fmi2FMUstate state)
{
    ENTER(fmi2SetFMUstate, ANY_STATE)
    Snapshot *snapshot = (Snapshot *)state;
    if (snapshot == NULL) return refuse(c, "fmi2SetFMUstate: FMUstate is NULL");
    fmi2Status status = c->bridge->setFMUstate(c->inner, snapshot->inner);
    if (status < fmi2Error) {
        c->state = snapshot->state;
        c->time = snapshot->time;
    }
    return after(c, status);
}

fmi2Status fmi2FreeFMUstate(fmi2Component component, fmi2FMUstate *state)
{
    ENTER(fmi2FreeFMUstate, ANY_STATE)
    if (state == NULL || *state == NULL) return fmi2OK;
    Snapshot *snapshot = (Snapshot *)*state;
    fmi2Status status = c->bridge->freeFMUstate(c->inner, &snapshot->inner);
    free(snapshot);
    *state = NULL;
    return after(c, status);
}

/* Serialized: a header (magic, state, CRC-32 of state, time and the slave's bytes, time), then the slave's bytes. */
typedef struct {
    char magic[8];
    uint32_t state;
    uint32_t crc;
    double time;
} Header;

static const char MAGIC[8] = "obsfmu\0\1";

static uint32_t crc32(uint32_t crc, const void *data, size_t size)
{
    const unsigned char *bytes = data;
    crc = ~crc;
    for (size_t i = 0; i < size; i++) {
        crc ^= bytes[i];
        for (int k = 0; k < 8; k++) crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
    }
    return ~crc;
}

static uint32_t checksum(const Header *header, const fmi2Byte *payload, size_t size)
{
    uint32_t crc = crc32(0, &header->state, sizeof header->state);
    crc = crc32(crc, &header->time, sizeof header->time);
    return crc32(crc, payload, size);
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component component, fmi2FMUstate state, size_t *size)
{
    ENTER(fmi2SerializedFMUstateSize, ANY_STATE)
    if (state == NULL || size == NULL) return refuse(c, "fmi2SerializedFMUstateSize: NULL argument");
    fmi2Status status = c->bridge->serializedFMUstateSize(c->inner, ((Snapshot *)state)->inner, size);
    if (status < fmi2Error) *size += sizeof(Header);
    return after(c, status);
}

fmi2Status fmi2SerializeFMUstate(fmi2Component component, fmi2FMUstate state, fmi2Byte buffer[], size_t size)
{
    ENTER(fmi2SerializeFMUstate, ANY_STATE)
    Snapshot *snapshot = (Snapshot *)state;
    size_t payload = 0;
    if (snapshot == NULL || buffer == NULL) return refuse(c, "fmi2SerializeFMUstate: NULL argument");
    fmi2Status status = c->bridge->serializedFMUstateSize(c->inner, snapshot->inner, &payload);
    if (status >= fmi2Error) return after(c, status);
    if (size < sizeof(Header) + payload)
        return refuse(c, "fmi2SerializeFMUstate: buffer of %zu bytes, %zu needed", size, sizeof(Header) + payload);
    status = c->bridge->serializeFMUstate(c->inner, snapshot->inner, buffer + sizeof(Header), payload);
    if (status >= fmi2Error) return after(c, status);
    Header header;
    memcpy(header.magic, MAGIC, sizeof MAGIC);
    header.state = (uint32_t)snapshot->state;
    header.time = snapshot->time;
    header.crc = checksum(&header, buffer + sizeof(Header), payload);
    memcpy(buffer, &header, sizeof header);
    return status;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component component, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *state)
{
    ENTER(fmi2DeSerializeFMUstate, ANY_STATE)
    Header header;
    if (serializedState == NULL || state == NULL) return refuse(c, "fmi2DeSerializeFMUstate: NULL argument");
    if (size < sizeof header) return refuse(c, "fmi2DeSerializeFMUstate: %zu bytes are not an FMU state", size);
    memcpy(&header, serializedState, sizeof header);
    const fmi2Byte *payload = serializedState + sizeof header;
    State saved = (State)header.state;
    if (memcmp(header.magic, MAGIC, sizeof MAGIC) != 0 || (saved & ANY_STATE) == 0 || (saved & (saved - 1)) != 0)
        return refuse(c, "fmi2DeSerializeFMUstate: not a serialized state of an obsfmu FMU of this version");
    if (checksum(&header, payload, size - sizeof header) != header.crc)
        return refuse(c, "fmi2DeSerializeFMUstate: the serialized state is damaged (checksum mismatch)");
    Snapshot *snapshot = *state ? (Snapshot *)*state : calloc(1, sizeof(Snapshot));
    if (snapshot == NULL) return refuse(c, "fmi2DeSerializeFMUstate: out of memory");
    fmi2Status status = c->bridge->deSerializeFMUstate(c->inner, payload, size - sizeof header, &snapshot->inner);
    if (status < fmi2Error) {
        snapshot->state = saved;
        snapshot->time = header.time;
        *state = snapshot;
    } else if (*state == NULL) {
        free(snapshot);
    }
    return after(c, status);
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
    ARRAYS(fmi2SetRealInputDerivatives, vr, nvr, value)
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
    (void)vr; (void)nvr; (void)order; (void)value;
    ENTER(fmi2GetRealOutputDerivatives, STEPPED)
    return refuse(c, "fmi2GetRealOutputDerivatives is not supported (maxOutputDerivativeOrder = 0)");
}

/* ---- stepping */

fmi2Status fmi2DoStep(fmi2Component component, fmi2Real currentCommunicationPoint,
                      fmi2Real communicationStepSize, fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    ENTER(fmi2DoStep, STEP_COMPLETE)
    double t = currentCommunicationPoint, h = communicationStepSize;
    if (!finite(h) || h <= 0)
        return refuse(c, "fmi2DoStep: communicationStepSize %g is not a positive finite number", h);
    if (!finite(t) || magnitude(t - c->time) > 1e-9 * (magnitude(c->time) > 1 ? magnitude(c->time) : 1))
        return refuse(c, "fmi2DoStep: currentCommunicationPoint %.17g is not the FMU's current time %.17g",
                      t, c->time);
    fmi2Status status = c->bridge->doStep(c->inner, t, h, noSetFMUStatePriorToCurrentPoint);
    if (status <= fmi2Warning) c->time = t + h;
    else if (status == fmi2Discard) c->state = STEP_FAILED;
    return after(c, status);
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
