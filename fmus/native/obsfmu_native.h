/*
 * What the two shared objects of an obsfmu FMU share (see docs/portability.md):
 *
 *   binaries/<platform>/<model>.so   the LOADER (loader.c): plain C, no Python symbols; exports
 *                                    the FMI 2.0 API, enforces the co-simulation state machine,
 *                                    finds or starts Python, then forwards to
 *   binaries/<platform>/<bridge>.so  the BRIDGE (bridge.c): compiled against one Python's headers,
 *                                    loaded RTLD_LOCAL; it exports only obsfmu_bridge(), the table
 *                                    of functions below, never fmi2* names.
 *
 * and resources/obsfmu_native.txt, the RECORD the builder writes (key=value lines).
 * Everything here is static: each shared object gets its own copy, nothing is exported.
 */
#ifndef OBSFMU_NATIVE_H
#define OBSFMU_NATIVE_H

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#ifdef _WIN32
#define WIN32_LEAN_AND_MEAN
#define NOGDI /* no wingdi.h: its ERROR macro is a state name of the loader */
#include <windows.h>
#undef ERROR
#endif

#include "fmi2FunctionTypes.h"

#define OBSFMU_RECORD "obsfmu_native.txt"
#define OBSFMU_STARTS "obsfmu_start.txt" /* start values of an exported copy (loader_common.h) */
#define OBSFMU_BRIDGE_SYMBOL "obsfmu_bridge"
#define OBSFMU_BRIDGE_ABI 4
/* The largest serialized FMU state read (fmi2DeSerializeFMUstate, fmi3DeserializeFMUState): refused beyond it
 * before a byte is copied.  = fmus.runtime.state_format.MAX_STATE_BYTES (tests/faults/test_faults_inputs.py). */
#define OBSFMU_MAX_STATE_BYTES ((size_t)64 << 20)

/* What the loader keeps in an FMU state (one serialized format: the slave's, fmus/runtime/state_format.py).
 * The loader hands `fmi` and `state` to the slave's getFMUstate; machineOf() gives them back from any
 * state (one it saved, or one the slave deserialized and checked), with the slave's own `time` and
 * `initialized` (the state was saved after exitInitializationMode), for the loader to validate. */
#define OBSFMU_STATE_NAME 32
typedef struct {
    int fmi;                          /* 2 or 3: the FMI version of the loader that saved the state */
    char state[OBSFMU_STATE_NAME];    /* the state machine's state, by name ("stepComplete", ...) */
    double time;                      /* out: the slave's time in the state (the loader's time too) */
    int initialized;                  /* out: 1 if saved after a successful exitInitializationMode */
} ObsfmuMachine;

/* The bridge's functions: the FMI 2.0 signatures (instance = the bridge's own component), plus
 * start() for a process without Python, the loader's fields of FMU states, and refused().
 *
 * Refused or failed: a call that returns fmi2Error was either REFUSED by the slave -- it raised its
 * refusal exception (BlockSlave.Refused) after checking the call and before changing anything: the
 * instance is exactly as before and usable -- or it FAILED (any other exception, or an error the slave
 * logged while carrying the call out: the instance may be inconsistent).  refused() says which, for the
 * bridge's last call on that component; the loader moves the instance to its failure state only when
 * the call failed. */
typedef struct {
    int abi;
    /* start the embedded interpreter once per process: libpython is already loaded RTLD_GLOBAL;
     * `program` is the python executable whose installation (and venv) to use. 0 on success. */
    int (*start)(const char *program, char *message, size_t size);
    fmi2InstantiateTYPE *instantiate;
    fmi2FreeInstanceTYPE *freeInstance;
    fmi2SetDebugLoggingTYPE *setDebugLogging;
    fmi2SetupExperimentTYPE *setupExperiment;
    fmi2EnterInitializationModeTYPE *enterInitializationMode;
    fmi2ExitInitializationModeTYPE *exitInitializationMode;
    fmi2TerminateTYPE *terminate;
    fmi2ResetTYPE *reset;
    fmi2GetRealTYPE *getReal;
    fmi2GetIntegerTYPE *getInteger;
    fmi2GetBooleanTYPE *getBoolean;
    fmi2GetStringTYPE *getString;
    fmi2SetRealTYPE *setReal;
    fmi2SetIntegerTYPE *setInteger;
    fmi2SetBooleanTYPE *setBoolean;
    fmi2SetStringTYPE *setString;
    /* the slave's state, with the loader's fields `fmi` and `state` of `machine` in it */
    fmi2Status (*getFMUstate)(fmi2Component c, const ObsfmuMachine *machine, fmi2FMUstate *state);
    /* the loader's fields of a state, with the slave's time and initialized (changes nothing) */
    fmi2Status (*machineOf)(fmi2Component c, fmi2FMUstate state, ObsfmuMachine *machine);
    fmi2SetFMUstateTYPE *setFMUstate;
    fmi2FreeFMUstateTYPE *freeFMUstate;
    fmi2SerializedFMUstateSizeTYPE *serializedFMUstateSize;
    fmi2SerializeFMUstateTYPE *serializeFMUstate;
    fmi2DeSerializeFMUstateTYPE *deSerializeFMUstate;
    fmi2SetRealInputDerivativesTYPE *setRealInputDerivatives;
    /* take back the input derivatives of these inputs (FMI 3.0: those of a discarded step's intermediate update) */
    fmi2Status (*clearInputDerivatives)(fmi2Component c, const fmi2ValueReference vr[], size_t nvr);
    fmi2DoStepTYPE *doStep;
    /* 1 if the bridge's last call on c returned fmi2Error because the slave refused it */
    int (*refused)(fmi2Component c);
    /* one communication step in one call (the loaders' obsfmuDoStepBatched): set the inputs `vr`
     * to `value` (and their first derivatives to `slope` unless NULL), step, read the outputs `out_vr`
     * into `out`; *stepped = 1 when the step was taken (then `out` is written) */
    fmi2Status (*doStepBatched)(fmi2Component c, fmi2Real t, fmi2Real h, const fmi2ValueReference vr[], size_t nvr,
                                const fmi2Real value[], const fmi2Real slope[], const fmi2ValueReference out_vr[],
                                size_t nout, fmi2Real out[], int *stepped);
    /* fmi2GetRealOutputDerivatives: first derivatives of outputs (FMUs with maxOutputDerivativeOrder = 1) */
    fmi2GetRealOutputDerivativesTYPE *getRealOutputDerivatives;
    /* the number of the slave's scalar variables (its value references 0 .. n-1) */
    size_t (*variableCount)(fmi2Component c);
    /* start() for a standalone FMU: its own runtime in `home` (libpython loaded RTLD_GLOBAL from there),
     * isolated (PYTHON* variables, user site ignored), the module search path the ':'-separated folders
     * `search` relative to `home`; nothing is written there (it may be read-only). 0 on success. */
    int (*startIsolated)(const char *home, const char *search, char *message, size_t size);
} ObsfmuBridge;

typedef const ObsfmuBridge *ObsfmuBridgeFunction(void);

/* ------------------------------------------------------------------ logging */

/* The message is passed as the format string with every '%' doubled and no variadic arguments:
 * correct for importers that format it (printf-style) and readable for those that cannot read
 * variadic arguments (fmpy without its logger proxy). */
static void obsfmu_emit(const fmi2CallbackFunctions *callbacks, const char *instance, fmi2Status status,
                        const char *category, const char *message)
{
    if (callbacks == NULL || callbacks->logger == NULL) return;
    size_t length = strlen(message), percents = 0;
    for (size_t i = 0; i < length; i++) percents += message[i] == '%';
    char *escaped = malloc(length + percents + 1);
    if (escaped == NULL) return;
    char *out = escaped;
    for (size_t i = 0; i < length; i++) {
        *out++ = message[i];
        if (message[i] == '%') *out++ = '%';
    }
    *out = '\0';
    callbacks->logger(callbacks->componentEnvironment, instance ? instance : "", status, category, escaped);
    free(escaped);
}

static const char *obsfmu_category(fmi2Status status)
{
    switch (status) {
    case fmi2Warning: return "logStatusWarning";
    case fmi2Discard: return "logStatusDiscard";
    case fmi2Error: return "logStatusError";
    case fmi2Fatal: return "logStatusFatal";
    default: return "logAll";
    }
}

/* ------------------------------------------------------------------ files, by UTF-8 path on every platform */

#ifdef _WIN32
/* A UTF-8 path as the UTF-16 path Windows' wide-character calls take, '/' turned into '\\' (LoadLibraryEx's
 * LOAD_WITH_ALTERED_SEARCH_PATH needs backslashes); malloc'ed, NULL when it is not UTF-8 (or out of memory). */
static inline wchar_t *obsfmu_wide(const char *path)
{
    int n = MultiByteToWideChar(CP_UTF8, MB_ERR_INVALID_CHARS, path, -1, NULL, 0);
    wchar_t *wide = n > 0 ? malloc((size_t)n * sizeof(wchar_t)) : NULL;
    if (wide == NULL || MultiByteToWideChar(CP_UTF8, MB_ERR_INVALID_CHARS, path, -1, wide, n) != n) {
        free(wide);
        return NULL;
    }
    for (wchar_t *c = wide; *c; c++)
        if (*c == L'/') *c = L'\\';
    return wide;
}

/* A UTF-16 string as UTF-8 into out (size bytes); "" when it does not fit. */
static inline void obsfmu_narrow(const wchar_t *wide, char *out, size_t size)
{
    if (size == 0) return;
    if (WideCharToMultiByte(CP_UTF8, 0, wide, -1, out, (int)size, NULL, NULL) <= 0) out[0] = '\0';
}

static inline FILE *obsfmu_fopen(const char *path, const char *mode)
{
    wchar_t *wide = obsfmu_wide(path), wmode[8];
    size_t i = 0;
    for (; mode[i] && i < 7; i++) wmode[i] = (wchar_t)mode[i];
    wmode[i] = L'\0';
    FILE *file = wide ? _wfopen(wide, wmode) : NULL;
    free(wide);
    return file;
}

/* 1 if `path` exists; *directory: it is a folder */
static inline int obsfmu_stat(const char *path, int *directory)
{
    wchar_t *wide = obsfmu_wide(path);
    DWORD attributes = wide ? GetFileAttributesW(wide) : INVALID_FILE_ATTRIBUTES;
    free(wide);
    if (attributes == INVALID_FILE_ATTRIBUTES) return 0;
    if (directory) *directory = (attributes & FILE_ATTRIBUTE_DIRECTORY) != 0;
    return 1;
}
#else
#define obsfmu_fopen fopen

static inline int obsfmu_stat(const char *path, int *directory)
{
    struct stat info;
    if (stat(path, &info) != 0) return 0;
    if (directory) *directory = S_ISDIR(info.st_mode);
    return 1;
}
#endif

/* ------------------------------------------------------------------ the resources folder */

static int obsfmu_hex(char digit)
{
    if (digit >= '0' && digit <= '9') return digit - '0';
    if (digit >= 'a' && digit <= 'f') return digit - 'a' + 10;
    if (digit >= 'A' && digit <= 'F') return digit - 'A' + 10;
    return -1;
}

/* file:///a%20b/resources, file:/a/resources or a plain path -> "/a b/resources" (malloc'ed); on Windows
 * file:///C:/a/resources -> "C:/a/resources" (the URI's UTF-8 bytes, decoded; obsfmu_wide for the API). */
static char *obsfmu_resource_path(const char *uri)
{
    const char *path = uri;
    if (strncmp(path, "file://", 7) == 0) {
        path += 7;
        if (strncmp(path, "localhost/", 10) == 0) path += 9;
    } else if (strncmp(path, "file:", 5) == 0) {
        path += 5;
    }
    char *decoded = malloc(strlen(path) + 1);
    if (decoded == NULL) return NULL;
    size_t j = 0;
    for (size_t i = 0; path[i]; i++) {
        if (path[i] == '%' && obsfmu_hex(path[i + 1]) >= 0 && obsfmu_hex(path[i + 2]) >= 0) {
            decoded[j++] = (char)(obsfmu_hex(path[i + 1]) * 16 + obsfmu_hex(path[i + 2]));
            i += 2;
        } else {
            decoded[j++] = path[i];
        }
    }
#ifdef _WIN32
    while (j > 1 && (decoded[j - 1] == '/' || decoded[j - 1] == '\\')) j--;
    decoded[j] = '\0';
    if (decoded[0] == '/' && decoded[1] && decoded[2] == ':') memmove(decoded, decoded + 1, j); /* /C:/x -> C:/x */
#else
    while (j > 1 && decoded[j - 1] == '/') j--;
    decoded[j] = '\0';
#endif
    return decoded;
}

/* Read <resources>/obsfmu_native.txt into a malloc'ed string; NULL (and errno) when unreadable. */
static char *obsfmu_read_record(const char *resources)
{
    size_t length = strlen(resources) + sizeof(OBSFMU_RECORD) + 2;
    char *name = malloc(length);
    if (name == NULL) return NULL;
    snprintf(name, length, "%s/%s", resources, OBSFMU_RECORD);
    FILE *file = obsfmu_fopen(name, "rb");
    free(name);
    if (file == NULL) return NULL;
    char *text = NULL;
    size_t size = 0;
    char chunk[4096];
    size_t got;
    while ((got = fread(chunk, 1, sizeof chunk, file)) > 0) {
        char *grown = realloc(text, size + got + 1);
        if (grown == NULL) {
            free(text);
            fclose(file);
            return NULL;
        }
        text = grown;
        memcpy(text + size, chunk, got);
        size += got;
    }
    fclose(file);
    if (text == NULL) text = calloc(1, 1);
    else text[size] = '\0';
    return text;
}

/* The platform's own keys of the record: an FMU with binaries for several platforms (obsfmu build --platform
 * linux64,win64) records what differs per platform -- the bridge, the Python, its runtime -- as "win64.<key>"
 * (fmus/builder.py); a loader of that platform reads them first. */
#if defined(_WIN32)
#define OBSFMU_PLATFORM_KEYS "win64."
#elif defined(__APPLE__)
#define OBSFMU_PLATFORM_KEYS "darwin64."
#else
#define OBSFMU_PLATFORM_KEYS ""
#endif

static int obsfmu_find_value(const char *record, const char *key, char *out, size_t size);

/* Copy the value of `key` (a line "key=value", or this platform's "<platform>.key=value", which wins even when
 * empty) into out; "" when absent or too long. */
static const char *obsfmu_record_value(const char *record, const char *key, char *out, size_t size)
{
    char own[256];
    if (OBSFMU_PLATFORM_KEYS[0] && strlen(key) + sizeof OBSFMU_PLATFORM_KEYS < sizeof own) {
        snprintf(own, sizeof own, "%s%s", OBSFMU_PLATFORM_KEYS, key);
        if (obsfmu_find_value(record, own, out, size)) return out;
    }
    obsfmu_find_value(record, key, out, size);
    return out;
}

/* 1 if the record has a line "key=value" (its value, or "" when too long, copied into out); else 0 and "". */
static int obsfmu_find_value(const char *record, const char *key, char *out, size_t size)
{
    size_t key_length = strlen(key);
    out[0] = '\0';
    for (const char *line = record; line && *line; line = strchr(line, '\n'), line = line ? line + 1 : NULL) {
        if (strncmp(line, key, key_length) == 0 && line[key_length] == '=') {
            const char *value = line + key_length + 1;
            size_t length = strcspn(value, "\r\n");
            if (length < size) {
                memcpy(out, value, length);
                out[length] = '\0';
            }
            return 1;
        }
    }
    return 0;
}

#endif
