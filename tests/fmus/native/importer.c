/*
 * A small FMI 2.0 co-simulation importer in plain C: the test suite's non-Python host.
 * It does not link libpython; it loads FMUs with dlopen(RTLD_NOW) and calls the FMI C API.  Cross-compiled with
 * MinGW-w64 it is a Windows host (win64 binaries, run under wine: test_windows.py).  A DIR or FILE may be
 * percent-encoded (spaces: %20).
 *
 *   importer SCRIPT      runs the commands of SCRIPT (one per line, in order, in ONE process):
 *
 *   fmu NAME DIR IDENTIFIER GUID    an FMI 2.0 FMU unzipped in DIR (binaries/linux64/IDENTIFIER.so)
 *   output NAME VR                  an output; outputs are numbered 0, 1, ... in this order
 *   input NAME VR SOURCE            an input fed by output number SOURCE
 *   feedthrough NAME                NAME has outputs that depend on its inputs
 *   start NAME real|integer VR X    a start value, set in initialization mode
 *
 *   fmu3 NAME DIR IDENTIFIER TOKEN  an FMI 3.0 FMU unzipped in DIR (binaries/x86_64-linux/IDENTIFIER.so);
 *                                   for it, instead of output/input/start (arrays: whole variables):
 *   output3 NAME VR COUNT           an output variable of COUNT elements (numbered on, like outputs)
 *   array3 NAME VR SIZE             an input variable of SIZE elements (set whole, in this order)
 *   input3 NAME VR INDEX SOURCE     element INDEX (from 0) of input variable VR fed by output SOURCE
 *   start3 NAME real|integer VR SIZE INDEX X
 *                                   element INDEX of the variable VR of SIZE elements starts at X
 *
 *   cosim jacobi linear|hold T0 T1 H FILE
 *                                   instantiate every FMU, co-simulate like fmus.master's Jacobi
 *                                   master (same rounds, same input coupling: FMI 2.0 input
 *                                   derivatives, or the FMI 3.0 intermediate update at t + h), write
 *                                   the outputs at every communication point to FILE (CSV), free them
 *   calls ID NAME IN OUT MODE CALL...
 *                                   a fresh instance of NAME; the FMI calls CALL... (see call())
 *                                   with IN a real input, OUT an output, MODE an Integer parameter;
 *                                   prints "call ID CALL STATUS [value]" per call
 *   bench NAME IN OUT N             times N calls each of getReal, getRealStatus and doStep, and the same
 *                                   loader-only call on a pointer the FMU never issued (the handle check)
 *   abuse ID NAME CASE VR...        FMI 2.0 or 3.0: a fresh instance in step mode, then the call sequence CASE
 *                                   that breaks the rules on handles or sizes (see abuse()), then a step that
 *                                   must work; prints "abuse ID WHAT STATUS" per call
 *   parallel NAME NAME              instantiate the two FMUs at once from two threads (both the first
 *                                   instantiations of the process when nothing ran before), step, free
 *   cycles NAME N                   N instantiate/initialize/step/free cycles; prints "memory K BYTES" on the way
 *   clear                           forget the declarations (a next system follows; libraries stay loaded)
 *
 * Log messages of the FMUs are printed as "log INSTANCE STATUS MESSAGE".
 */
#ifdef _WIN32
/* the win64 build (cross-compiled with MinGW-w64, run under wine: test_windows.py): dlopen over LoadLibraryExW */
#define WIN32_LEAN_AND_MEAN
#include <windows.h>
#include <psapi.h>
#include <stdio.h>
#define PLATFORM "win64"
#define PLATFORM3 "x86_64-windows"
#define SUFFIX ".dll"
#define RTLD_NOW 0
#define RTLD_LOCAL 0
static char dl_message[64];
/* a UTF-8 path (the script's) as UTF-16 with backslashes: LoadLibraryExW finds the DLL's neighbours */
static void *dlopen(const char *path, int mode)
{
    (void)mode;
    wchar_t wide[4200];
    if (!MultiByteToWideChar(CP_UTF8, 0, path, -1, wide, 4200)) return NULL;
    for (wchar_t *c = wide; *c; c++) if (*c == L'/') *c = L'\\';
    void *library = (void *)LoadLibraryExW(wide, NULL, LOAD_WITH_ALTERED_SEARCH_PATH);
    snprintf(dl_message, sizeof dl_message, "LoadLibraryExW: Windows error %lu", (unsigned long)GetLastError());
    return library;
}
static void *dlsym(void *library, const char *name) { return (void *)GetProcAddress((HMODULE)library, name); }
/* fopen of a UTF-8 path (the script's CSV may be in a folder with non-ASCII letters) */
static FILE *open_utf8(const char *path, const char *mode)
{
    wchar_t wide[4200], wmode[8];
    if (!MultiByteToWideChar(CP_UTF8, 0, path, -1, wide, 4200) || !MultiByteToWideChar(CP_UTF8, 0, mode, -1, wmode, 8))
        return NULL;
    return _wfopen(wide, wmode);
}
static const char *dlerror(void) { return dl_message; }
#else
#include <dlfcn.h>
#define PLATFORM "linux64"
#define PLATFORM3 "x86_64-linux"
#define SUFFIX ".so"
#define open_utf8 fopen
#endif
#include <math.h>
#include <pthread.h>
#include <stdint.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "fmi2Functions.h"
#include "fmi3Functions.h"

#define FMI(X) X(Instantiate) X(FreeInstance) X(SetupExperiment) X(EnterInitializationMode)                  \
    X(ExitInitializationMode) X(Terminate) X(Reset) X(GetReal) X(GetInteger) X(GetBoolean) X(GetString)       \
    X(SetReal) X(SetInteger) X(SetBoolean) X(SetString) X(GetFMUstate) X(SetFMUstate) X(FreeFMUstate)         \
    X(SerializedFMUstateSize) X(SerializeFMUstate) X(DeSerializeFMUstate) X(GetDirectionalDerivative)         \
    X(SetRealInputDerivatives) X(GetRealOutputDerivatives) X(DoStep) X(CancelStep) X(GetStatus)               \
    X(GetRealStatus) X(GetIntegerStatus) X(GetBooleanStatus) X(GetStringStatus) X(SetDebugLogging)

#define FMI3(X) X(InstantiateCoSimulation) X(FreeInstance) X(EnterInitializationMode) X(ExitInitializationMode)     \
    X(Terminate) X(GetFloat64) X(SetFloat64) X(GetInt32) X(SetInt32) X(DoStep) X(GetFMUState) X(SetFMUState)          \
    X(FreeFMUState) X(SerializedFMUStateSize)

#define MAX 64

typedef struct {
#define MEMBER(f) fmi2##f##TYPE *f;
    FMI(MEMBER)
    struct {
#define MEMBER3(f) fmi3##f##TYPE *f;
        FMI3(MEMBER3)
    } v3;
    int version; /* 2 or 3 */
    char name[64], resources[4200], guid[128];
    fmi2Component c;
    int outputs, output_index[MAX], inputs, input_source[MAX], feedthrough;
    fmi2ValueReference output_vr[MAX], input_vr[MAX];
    int starts, start_integer[MAX], start_size[MAX], start_index[MAX];
    fmi2ValueReference start_vr[MAX];
    double start_value[MAX];
    /* FMI 3.0: output variables (their elements are outputs output_index[0], +1, ...), input variables
     * kept in one buffer, the wired elements' places in it, and their slopes over the current step */
    int output_arrays, output_count[MAX], arrays, array_size[MAX], array_offset[MAX], input_position[MAX];
    fmi3ValueReference output_array_vr[MAX], array_vr[MAX];
    double buffer[MAX], slopes[MAX], step_start;
    int linear;
} Fmu;

static Fmu fmus[16];
static int count, total_outputs;

static void die(const char *message, const char *detail)
{
    fprintf(stderr, "importer: %s %s\n", message, detail ? detail : "");
    exit(2);
}

static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    (void)env; (void)category;
    va_list args;
    va_start(args, message);
    printf("log %s %d ", instance, status);
    vprintf(message, args);
    printf("\n");
    va_end(args);
    fflush(stdout);
}

/* canNotUseMemoryManagementFunctions = true: no allocator is given */
static const fmi2CallbackFunctions callbacks = {logger, NULL, NULL, NULL, NULL};

static Fmu *find(const char *name)
{
    for (int i = 0; i < count; i++)
        if (strcmp(fmus[i].name, name) == 0) return &fmus[i];
    die("no FMU named", name);
    return NULL;
}

/* "%41%20b" -> "A b", in place (a script's DIR may hold spaces: the harness writes them percent-encoded) */
static char *decoded(char *text)
{
    char *out = text;
    for (const char *in = text; *in; in++) {
        unsigned byte;
        if (in[0] == '%' && sscanf(in + 1, "%2x", &byte) == 1) {
            *out++ = (char)byte;
            in += 2;
        } else {
            *out++ = *in;
        }
    }
    *out = '\0';
    return text;
}

/* the file URI of a UTF-8 path, as fmpy writes it: file:///a%20b/... (Windows: file:///C:/a%20b/...) */
static void file_uri(char *uri, size_t size, const char *path)
{
    size_t n = (size_t)snprintf(uri, size, "file://%s", path[0] == '/' ? "" : "/");
    for (const unsigned char *c = (const unsigned char *)path; *c && n + 4 < size; c++) {
        if ((*c >= 'a' && *c <= 'z') || (*c >= 'A' && *c <= 'Z') || (*c >= '0' && *c <= '9') || strchr("-._~/:", *c))
            uri[n++] = (char)*c;
        else
            n += (size_t)snprintf(uri + n, size - n, "%%%02X", *c);
    }
    uri[n] = '\0';
}

static void load(Fmu *f, const char *directory, const char *identifier)
{
    char path[4200], resources[4200];
    snprintf(path, sizeof path, "%s/binaries/" PLATFORM "/%s" SUFFIX, directory, identifier);
    void *library = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (library == NULL) die("dlopen:", dlerror());
#define LOAD(f_) if ((f->f_ = (fmi2##f_##TYPE *)dlsym(library, "fmi2" #f_)) == NULL) die("missing fmi2" #f_, path);
    FMI(LOAD)
    snprintf(resources, sizeof resources, "%s/resources", directory);
    file_uri(f->resources, sizeof f->resources, resources);
}

/* FMI 3.0 logMessage: printed like the FMI 2.0 logger's messages */
static void log3(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message)
{
    (void)category;
    printf("log %s %d %s\n", env ? ((Fmu *)env)->name : "?", status, message);
    fflush(stdout);
}

static void load3(Fmu *f, const char *directory, const char *identifier)
{
    char path[4200];
    snprintf(path, sizeof path, "%s/binaries/" PLATFORM3 "/%s" SUFFIX, directory, identifier);
    void *library = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (library == NULL) die("dlopen:", dlerror());
#define LOAD3(f_) if ((f->v3.f_ = (fmi3##f_##TYPE *)dlsym(library, "fmi3" #f_)) == NULL) die("missing fmi3" #f_, path);
    FMI3(LOAD3)
    snprintf(f->resources, sizeof f->resources, "%s/resources/", directory);
    f->version = 3;
}

static double now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + 1e-9 * t.tv_nsec;
}

static fmi2Component instantiate(Fmu *f, const char *guid)
{
    double begin = now();
    fmi2Component c = f->Instantiate(f->name, fmi2CoSimulation, guid, f->resources, &callbacks, fmi2False, fmi2False);
    printf("instantiate %s %s %.6f\n", f->name, c ? "ok" : "null", now() - begin);
    return c;
}

/* FMI 3.0 intermediate update (inside fmi3DoStep): the inputs at `time` on the line of the step */
static void intermediate(fmi3InstanceEnvironment env, fmi3Float64 time, fmi3Boolean set_requested,
                         fmi3Boolean get_allowed, fmi3Boolean finished, fmi3Boolean can_return_early,
                         fmi3Boolean *early_return, fmi3Float64 *early_time)
{
    (void)get_allowed; (void)finished; (void)can_return_early; (void)early_return; (void)early_time;
    Fmu *f = (Fmu *)env;
    double ends[MAX];
    if (!set_requested || !f->linear || f->arrays == 0) return;
    int total = f->array_offset[f->arrays - 1] + f->array_size[f->arrays - 1];
    for (int k = 0; k < total; k++) ends[k] = f->buffer[k] + (time - f->step_start) * f->slopes[k];
    if (f->v3.SetFloat64(f->c, f->array_vr, f->arrays, ends, total) > fmi3Warning) die("intermediate update of", f->name);
}

static fmi2Component instantiate3(Fmu *f, int linear)
{
    double begin = now();
    f->linear = linear;
    fmi3Instance c = f->v3.InstantiateCoSimulation(f->name, f->guid, f->resources, fmi3False, fmi3True, fmi3False,
                                                   fmi3False, f->array_vr, linear ? f->arrays : 0, f, log3,
                                                   linear ? intermediate : NULL);
    printf("instantiate %s %s %.6f\n", f->name, c ? "ok" : "null", now() - begin);
    return c;
}

static void check(fmi2Status status, Fmu *f, const char *what)
{
    if (status > fmi2Warning) {
        fprintf(stderr, "importer: %s.%s returned %d\n", f->name, what, status);
        exit(3);
    }
}

/* ------------------------------------------------------------------ the Jacobi master */

static double live[MAX * 4], now_values[MAX * 4], before[MAX * 4];

static void set_inputs3(Fmu *f, const double *source, const double *slopes)
{
    if (f->arrays == 0) return;
    for (int i = 0; i < f->inputs; i++) {
        f->buffer[f->input_position[i]] = source[f->input_source[i]];
        f->slopes[f->input_position[i]] = slopes ? slopes[f->input_source[i]] : 0.0;
    }
    int total = f->array_offset[f->arrays - 1] + f->array_size[f->arrays - 1];
    check(f->v3.SetFloat64(f->c, f->array_vr, f->arrays, f->buffer, total), f, "SetFloat64");
}

static void set_inputs(Fmu *f, const double *source, const double *slopes)
{
    double values[MAX], derivatives[MAX];
    fmi2Integer orders[MAX];
    if (f->version == 3) {
        set_inputs3(f, source, slopes);
        return;
    }
    if (f->inputs == 0) return;
    for (int i = 0; i < f->inputs; i++) {
        values[i] = source[f->input_source[i]];
        derivatives[i] = slopes ? slopes[f->input_source[i]] : 0.0;
        orders[i] = 1;
    }
    check(f->SetReal(f->c, f->input_vr, f->inputs, values), f, "SetReal");
    if (slopes) check(f->SetRealInputDerivatives(f->c, f->input_vr, f->inputs, orders, derivatives), f, "SetRealInputDerivatives");
}

static void refresh(Fmu *f)
{
    double values[MAX];
    if (f->version == 3) {
        if (f->outputs) check(f->v3.GetFloat64(f->c, f->output_array_vr, f->output_arrays, values, f->outputs), f,
                              "GetFloat64");
    } else {
        check(f->GetReal(f->c, f->output_vr, f->outputs, values), f, "GetReal");
    }
    for (int i = 0; i < f->outputs; i++) live[f->output_index[i]] = values[i];
}

static void settle(int passes)
{
    for (int p = 0; p < passes; p++)
        for (int i = 0; i < count; i++) {
            set_inputs(&fmus[i], live, NULL);
            refresh(&fmus[i]);
        }
}

static void record(FILE *csv, double t)
{
    fprintf(csv, "%.17g", t);
    for (int j = 0; j < total_outputs; j++) fprintf(csv, ",%.17g", live[j]);
    fprintf(csv, "\n");
}

static fmi2Status do_step(Fmu *f, double t, double h)
{
    if (f->version != 3) return f->DoStep(f->c, t, h, fmi2True);
    fmi3Boolean event, terminate, early;
    fmi3Float64 last;
    f->step_start = t;
    return (fmi2Status)f->v3.DoStep(f->c, t, h, fmi3True, &event, &terminate, &early, &last);
}

static void cosim(int linear, double start, double stop, double step, const char *file)
{
    FILE *csv = open_utf8(file, "w");
    if (csv == NULL) die("cannot write", file);
    int feedthrough = 0;
    for (int i = 0; i < count; i++) {
        Fmu *f = &fmus[i];
        if (f->version == 3) {
            if ((f->c = instantiate3(f, linear)) == NULL) die("fmi3InstantiateCoSimulation failed for", f->name);
            check(f->v3.EnterInitializationMode(f->c, fmi3False, 0.0, start, fmi3True, stop), f,
                  "EnterInitializationMode");
        } else {
            if ((f->c = instantiate(f, f->guid)) == NULL) die("fmi2Instantiate failed for", f->name);
            check(f->SetupExperiment(f->c, fmi2False, 0.0, start, fmi2True, stop), f, "SetupExperiment");
            check(f->EnterInitializationMode(f->c), f, "EnterInitializationMode");
        }
        feedthrough += f->feedthrough;
    }
    for (int i = 0; i < count; i++) {
        Fmu *f = &fmus[i];
        for (int s = 0; s < f->starts; s++) {
            fmi2Integer integer = (fmi2Integer)f->start_value[s];
            if (f->version == 3) { /* the element's variable, set whole */
                double whole[MAX];
                fmi3ValueReference vr = f->start_vr[s];
                if (f->start_integer[s]) {
                    check(f->v3.SetInt32(f->c, &vr, 1, &integer, 1), f, "start value");
                    continue;
                }
                check(f->v3.GetFloat64(f->c, &vr, 1, whole, f->start_size[s]), f, "GetFloat64 (start value)");
                whole[f->start_index[s]] = f->start_value[s];
                check(f->v3.SetFloat64(f->c, &vr, 1, whole, f->start_size[s]), f, "start value");
                continue;
            }
            check(f->start_integer[s] ? f->SetInteger(f->c, &f->start_vr[s], 1, &integer)
                                      : f->SetReal(f->c, &f->start_vr[s], 1, &f->start_value[s]), f, "start value");
        }
        if (f->version == 3 && f->arrays) { /* the inputs' own values for the elements nobody feeds */
            int total = f->array_offset[f->arrays - 1] + f->array_size[f->arrays - 1];
            check(f->v3.GetFloat64(f->c, f->array_vr, f->arrays, f->buffer, total), f, "GetFloat64 (inputs)");
        }
    }
    settle(count + 1);
    for (int i = 0; i < count; i++) {
        check(fmus[i].version == 3 ? (fmi2Status)fmus[i].v3.ExitInitializationMode(fmus[i].c)
                                   : fmus[i].ExitInitializationMode(fmus[i].c), &fmus[i], "ExitInitializationMode");
        refresh(&fmus[i]);
    }
    memcpy(now_values, live, sizeof live);
    record(csv, start);
    int steps = (int)ceil((stop - start) / step - 1e-9), have_before = 0;
    double h_before = 0.0, slopes[MAX * 4];
    for (int k = 0; k < steps; k++) {
        double t = fmin(start + step * k, stop), next = fmin(start + step * (k + 1), stop);
        double h = k < steps - 1 ? step : next - t;
        for (int j = 0; j < total_outputs; j++) slopes[j] = have_before ? (now_values[j] - before[j]) / h_before : 0.0;
        for (int i = 0; i < count; i++) { /* every FMU steps from the outputs at t */
            set_inputs(&fmus[i], now_values, linear ? slopes : NULL);
            check(do_step(&fmus[i], t, h), &fmus[i], "DoStep");
            refresh(&fmus[i]);
        }
        if (feedthrough) settle(feedthrough);
        memcpy(before, now_values, sizeof live);
        memcpy(now_values, live, sizeof live);
        h_before = h;
        have_before = 1;
        record(csv, next);
    }
    for (int i = 0; i < count; i++) {
        if (fmus[i].version == 3) {
            check((fmi2Status)fmus[i].v3.Terminate(fmus[i].c), &fmus[i], "Terminate");
            fmus[i].v3.FreeInstance(fmus[i].c);
        } else {
            check(fmus[i].Terminate(fmus[i].c), &fmus[i], "Terminate");
            fmus[i].FreeInstance(fmus[i].c);
        }
        fmus[i].c = NULL;
    }
    fclose(csv);
}

/* ------------------------------------------------------------------ single calls (state machine) */

static double current_time;

/* One FMI call named `call` (variants after ':'); returns its status, prints a value for readers. */
static int call(Fmu *f, const char *call, fmi2ValueReference in, fmi2ValueReference out, fmi2ValueReference mode,
                fmi2FMUstate initial, fmi2Byte *bytes, size_t size, double *value)
{
    fmi2Component c = f->c;
    double x = 0.0, one = 1.0, nan_value = NAN;
    fmi2Integer integer = 1, order = 1;
    fmi2Boolean flag;
    fmi2FMUstate state = NULL;
    size_t length;
    fmi2Status s, status_value;
    fmi2String text;
    if (!strcmp(call, "setupExperiment")) { s = f->SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0); if (s <= fmi2Warning) current_time = 0; return s; }
    if (!strcmp(call, "enterInitializationMode")) return f->EnterInitializationMode(c);
    if (!strcmp(call, "exitInitializationMode")) return f->ExitInitializationMode(c);
    if (!strcmp(call, "terminate")) return f->Terminate(c);
    if (!strcmp(call, "reset")) return f->Reset(c);
    if (!strcmp(call, "setDebugLogging")) return f->SetDebugLogging(c, fmi2True, 0, NULL);
    if (!strcmp(call, "getReal")) { s = f->GetReal(c, &out, 1, value); return s; }
    if (!strcmp(call, "getReal:bad")) { fmi2ValueReference bad = 999999; return f->GetReal(c, &bad, 1, &x); }
    if (!strcmp(call, "getInteger")) return f->GetInteger(c, &mode, 1, &integer);
    if (!strcmp(call, "getBoolean")) return f->GetBoolean(c, NULL, 0, NULL);
    if (!strcmp(call, "getString")) return f->GetString(c, NULL, 0, NULL);
    if (!strcmp(call, "setReal")) return f->SetReal(c, &in, 1, &x);
    if (!strcmp(call, "setReal:nan")) return f->SetReal(c, &in, 1, &nan_value);
    if (!strcmp(call, "setInteger")) return f->SetInteger(c, &mode, 1, &integer);
    if (!strcmp(call, "setInteger:7")) { integer = 7; return f->SetInteger(c, &mode, 1, &integer); }
    if (!strcmp(call, "setBoolean")) return f->SetBoolean(c, NULL, 0, NULL);
    if (!strcmp(call, "setString")) return f->SetString(c, NULL, 0, NULL);
    if (!strcmp(call, "getFMUstate")) { s = f->GetFMUstate(c, &state); if (state) f->FreeFMUstate(c, &state); return s; }
    if (!strcmp(call, "setFMUstate")) return f->SetFMUstate(c, initial);
    if (!strcmp(call, "freeFMUstate")) return f->FreeFMUstate(c, &state);
    if (!strcmp(call, "serializedFMUstateSize")) return f->SerializedFMUstateSize(c, initial, &length);
    if (!strcmp(call, "serializeFMUstate")) { fmi2Byte *b = malloc(size); s = f->SerializeFMUstate(c, initial, b, size); free(b); return s; }
    if (!strcmp(call, "deSerializeFMUstate") || !strcmp(call, "deSerializeFMUstate:flipped")) {
        if (strchr(call, ':')) bytes[size / 2] ^= 0x10;
        s = f->DeSerializeFMUstate(c, bytes, size, &state);
        if (strchr(call, ':')) bytes[size / 2] ^= 0x10;
        if (state) f->FreeFMUstate(c, &state);
        return s;
    }
    if (!strcmp(call, "getDirectionalDerivative")) return f->GetDirectionalDerivative(c, &out, 1, &in, 1, &one, &x);
    if (!strcmp(call, "setRealInputDerivatives")) return f->SetRealInputDerivatives(c, &in, 1, &order, &x);
    if (!strcmp(call, "setRealInputDerivatives:order2")) { order = 2; return f->SetRealInputDerivatives(c, &in, 1, &order, &one); }
    if (!strcmp(call, "getRealOutputDerivatives")) return f->GetRealOutputDerivatives(c, &out, 1, &order, &x);
    if (!strncmp(call, "doStep", 6)) {
        double t = current_time, h = 1e-3;
        if (!strcmp(call, "doStep:late")) t += 1.0;
        else if (!strcmp(call, "doStep:tnan")) t = NAN;
        else if (!strcmp(call, "doStep:h0")) h = 0.0;
        else if (!strcmp(call, "doStep:hneg")) h = -1e-3;
        else if (!strcmp(call, "doStep:hnan")) h = NAN;
        else if (!strcmp(call, "doStep:hinf")) h = INFINITY;
        else if (!strcmp(call, "doStep:tnear")) t += 1e-12; /* within the 1e-9 tolerance */
        s = f->DoStep(c, t, h, fmi2True);
        if (s <= fmi2Warning) current_time = t + h;
        return s;
    }
    if (!strcmp(call, "cancelStep")) return f->CancelStep(c);
    if (!strcmp(call, "getStatus")) return f->GetStatus(c, fmi2DoStepStatus, &status_value);
    if (!strcmp(call, "getRealStatus")) return f->GetRealStatus(c, fmi2LastSuccessfulTime, value);
    if (!strcmp(call, "getIntegerStatus")) return f->GetIntegerStatus(c, fmi2DoStepStatus, &integer);
    if (!strcmp(call, "getBooleanStatus")) return f->GetBooleanStatus(c, fmi2Terminated, &flag);
    if (!strcmp(call, "getStringStatus")) return f->GetStringStatus(c, fmi2PendingStatus, &text);
    die("unknown call", call);
    return -1;
}

static void calls(const char *id, Fmu *f, fmi2ValueReference in, fmi2ValueReference out, fmi2ValueReference mode,
                  char **tokens, int n)
{
    fmi2FMUstate initial = NULL;
    size_t size = 0;
    printf("case %s\n", id);
    if (!strcmp(tokens[0], "instantiate:badguid")) {
        fmi2Component c = instantiate(f, "{not-the-guid}");
        printf("call %s instantiate:badguid %s\n", id, c ? "ok" : "null");
        if (c) f->FreeInstance(c);
        return;
    }
    if ((f->c = instantiate(f, f->guid)) == NULL) die("fmi2Instantiate failed for", f->name);
    current_time = 0.0;
    check(f->GetFMUstate(f->c, &initial), f, "GetFMUstate");
    check(f->SerializedFMUstateSize(f->c, initial, &size), f, "SerializedFMUstateSize");
    fmi2Byte *bytes = malloc(size);
    check(f->SerializeFMUstate(f->c, initial, bytes, size), f, "SerializeFMUstate");
    for (int i = 0; i < n; i++) {
        double value = NAN;
        int status = call(f, tokens[i], in, out, mode, initial, bytes, size, &value);
        printf("call %s %s %d %.17g\n", id, tokens[i], status, value);
        fflush(stdout);
    }
    f->FreeFMUstate(f->c, &initial);
    free(bytes);
    f->FreeInstance(f->c);
    f->c = NULL;
}

static void bench(Fmu *f, fmi2ValueReference in, fmi2ValueReference out, long n)
{
    double x, begin;
    (void)in;
    if ((f->c = instantiate(f, f->guid)) == NULL) die("fmi2Instantiate failed for", f->name);
    check(f->SetupExperiment(f->c, fmi2False, 0.0, 0.0, fmi2False, 0.0), f, "SetupExperiment");
    check(f->EnterInitializationMode(f->c), f, "EnterInitializationMode");
    check(f->ExitInitializationMode(f->c), f, "ExitInitializationMode");
    begin = now();
    for (long i = 0; i < n; i++) f->GetRealStatus(f->c, fmi2LastSuccessfulTime, &x);
    printf("bench loader-only fmi2GetRealStatus %.3e s/call\n", (now() - begin) / n);
    begin = now();
    for (long i = 0; i < n; i++) f->GetReal(f->c, &out, 1, &x);
    printf("bench through-bridge fmi2GetReal %.3e s/call\n", (now() - begin) / n);
    begin = now();
    for (long i = 0; i < n; i++) check(f->DoStep(f->c, i * 1e-3, 1e-3, fmi2True), f, "DoStep");
    printf("bench through-bridge fmi2DoStep %.3e s/call\n", (now() - begin) / n);
    void *foreign = calloc(1, 4096);   /* a pointer the FMU never issued: refused by the handle check alone */
    begin = now();
    for (long i = 0; i < n; i++) f->GetRealStatus(foreign, fmi2LastSuccessfulTime, &x);
    printf("bench loader-only fmi2GetRealStatus-foreign %.3e s/call\n", (now() - begin) / n);
    free(foreign);
    f->FreeInstance(f->c);
    f->c = NULL;
}

/* ------------------------------------------------------------------ abusive call sequences (handles, sizes) */

/* An instance in step mode (FMI 2.0 stepComplete, FMI 3.0 stepMode); NULL dies. */
static void *stepping(Fmu *f)
{
    void *c;
    if (f->version == 3) {
        c = f->v3.InstantiateCoSimulation(f->name, f->guid, f->resources, fmi3False, fmi3True, fmi3False, fmi3False,
                                          NULL, 0, f, log3, NULL);
        if (c == NULL) die("fmi3InstantiateCoSimulation failed for", f->name);
        check((fmi2Status)f->v3.EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3False, 0.0), f, "EnterInitializationMode");
        check((fmi2Status)f->v3.ExitInitializationMode(c), f, "ExitInitializationMode");
        return c;
    }
    if ((c = instantiate(f, f->guid)) == NULL) die("fmi2Instantiate failed for", f->name);
    check(f->SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0), f, "SetupExperiment");
    check(f->EnterInitializationMode(c), f, "EnterInitializationMode");
    check(f->ExitInitializationMode(c), f, "ExitInitializationMode");
    return c;
}

static double abuse_time;

static int step_of(Fmu *f, void *c)
{
    fmi2Component saved = f->c;
    f->c = c;
    fmi2Status s = do_step(f, abuse_time, 1e-3);
    f->c = saved;
    if (s <= fmi2Warning) abuse_time += 1e-3;
    return s;
}

static int get_state(Fmu *f, void *c, void **s) { return f->version == 3 ? (int)f->v3.GetFMUState(c, s) : f->GetFMUstate(c, s); }
static int set_state(Fmu *f, void *c, void *s) { return f->version == 3 ? (int)f->v3.SetFMUState(c, s) : f->SetFMUstate(c, s); }
static int free_state(Fmu *f, void *c, void **s) { return f->version == 3 ? (int)f->v3.FreeFMUState(c, s) : f->FreeFMUstate(c, s); }
static int state_size(Fmu *f, void *c, void *s, size_t *n)
{
    return f->version == 3 ? (int)f->v3.SerializedFMUStateSize(c, s, n) : f->SerializedFMUstateSize(c, s, n);
}
static void free_instance(Fmu *f, void *c) { if (f->version == 3) f->v3.FreeInstance(c); else f->FreeInstance(c); }
static int get_real(Fmu *f, void *c, const unsigned *vr, size_t nvr, double *x, size_t nx)
{
    return f->version == 3 ? (int)f->v3.GetFloat64(c, vr, nvr, x, nx) : f->GetReal(c, vr, nvr, x);
}

#define SAY(what, status) (printf("abuse %s %s %d\n", id, what, (int)(status)), fflush(stdout))

/* The call sequences real importers commit (docs/portability.md, "Handles"); every call is printed with
 * its status, then a step of a valid instance of the process must still work ("abuse ID last-step 0"). */
static void abuse(const char *id, Fmu *f, const char *name, char **vrs, int nvrs)
{
    unsigned char *junk = malloc(4096);           /* a pointer the FMU never issued, full of garbage */
    memset(junk, 0xAB, 4096);
    junk[0] = 1;                                  /* as if a reference count of 1 came first */
    memset(junk + 1, 0, 7);
    void *c = stepping(f), *s = NULL, *t;
    double x[MAX];
    unsigned vr = 0;
    size_t n = 0, big = (size_t)1 << 40;
    abuse_time = 0.0;
    if (!strcmp(name, "foreign-instance")) {
        SAY("doStep", step_of(f, junk));
        SAY("getReal", get_real(f, junk, &vr, 1, x, 1));
        SAY("getFMUstate", get_state(f, junk, &s));
        free_instance(f, junk);
    } else if (!strcmp(name, "free-twice")) {
        free_instance(f, c);
        free_instance(f, c);
        c = stepping(f);
    } else if (!strcmp(name, "use-after-free")) {
        free_instance(f, c);
        SAY("doStep", step_of(f, c));
        SAY("getReal", get_real(f, c, &vr, 1, x, 1));
        SAY("getFMUstate", get_state(f, c, &s));
        c = stepping(f);
    } else if (!strcmp(name, "state-after-free")) {
        SAY("getFMUstate", get_state(f, c, &s));
        t = s;
        SAY("freeFMUstate", free_state(f, c, &s));
        SAY("setFMUstate", set_state(f, c, t));
        SAY("serializedFMUstateSize", state_size(f, c, t, &n));
        SAY("freeFMUstate-again", free_state(f, c, &t));
    } else if (!strcmp(name, "free-state-itself")) {   /* fmusim 0.0.39: free(c, s) instead of free(c, &s) */
        SAY("getFMUstate", get_state(f, c, &s));
        SAY("freeFMUstate-itself", free_state(f, c, (void **)s));
        SAY("setFMUstate", set_state(f, c, s));
        SAY("freeFMUstate", free_state(f, c, &s));
    } else if (!strcmp(name, "uninitialised-state")) {
        s = junk;
        SAY("getFMUstate", get_state(f, c, &s));
        SAY("unchanged", s == (void *)junk ? 0 : 3);
    } else if (!strcmp(name, "foreign-state")) {
        SAY("setFMUstate", set_state(f, c, junk));
        SAY("serializedFMUstateSize", state_size(f, c, junk, &n));
        s = junk;
        SAY("freeFMUstate", free_state(f, c, &s));
    } else if (!strcmp(name, "leaked-states")) {       /* states the importer never frees: freed with the instance */
        for (int k = 0; k < 3; k++) {
            s = NULL;
            SAY("getFMUstate", get_state(f, c, &s));
        }
        free_instance(f, c);
        c = stepping(f);
    } else if (!strcmp(name, "huge-nvr")) {
        SAY("getReal-2^40", get_real(f, c, &vr, big, x, big));
        SAY("getReal-SIZE_MAX", get_real(f, c, &vr, SIZE_MAX, x, SIZE_MAX));
        if (f->version == 3) {
            fmi3Int32 i32[1];
            SAY("setFloat64-2^40", f->v3.SetFloat64(c, &vr, big, x, big));
            SAY("getInt32-SIZE_MAX", f->v3.GetInt32(c, &vr, SIZE_MAX, i32, SIZE_MAX));
            SAY("setInt32-2^40", f->v3.SetInt32(c, &vr, big, i32, big));
        } else {
            fmi2Integer i32[1], order[1] = {1};
            fmi2Boolean b[1];
            SAY("setReal-2^40", f->SetReal(c, &vr, big, x));
            SAY("getInteger-SIZE_MAX", f->GetInteger(c, &vr, SIZE_MAX, i32));
            SAY("setInteger-2^40", f->SetInteger(c, &vr, big, i32));
            SAY("getBoolean-2^40", f->GetBoolean(c, &vr, big, b));
            SAY("setRealInputDerivatives-2^40", f->SetRealInputDerivatives(c, &vr, big, order, x));
        }
    } else if (!strcmp(name, "every-variable")) {      /* VR...: a whole type's variables, `time` included */
        unsigned list[MAX];
        size_t values = (size_t)atol(vrs[0]);
        for (int k = 1; k < nvrs; k++) list[k - 1] = (unsigned)atol(vrs[k]);
        double *all = calloc(values + 1, sizeof(double));
        SAY("getFloat64-every", get_real(f, c, list, (size_t)(nvrs - 1), all, values));
        SAY("time", all[0] == 0.0 ? 0 : 3);
        free(all);
    } else {
        die("unknown abuse", name);
    }
    SAY("last-step", step_of(f, c));
    free_instance(f, c);
    free(junk);
}

/* ------------------------------------------------------------------ two first instantiations at once */

static pthread_barrier_t together;

static void *instantiate_at_once(void *argument)
{
    Fmu *f = argument;
    pthread_barrier_wait(&together);
    void *c = stepping(f);
    fmi2Component saved = f->c;
    f->c = c;
    for (int k = 0; k < 3; k++) check(do_step(f, k * 1e-3, 1e-3), f, "DoStep");
    f->c = saved;
    free_instance(f, c);
    printf("parallel %s ok\n", f->name);
    fflush(stdout);
    return NULL;
}

static void parallel(Fmu *a, Fmu *b)
{
    pthread_t threads[2];
    pthread_barrier_init(&together, NULL, 2);
    pthread_create(&threads[0], NULL, instantiate_at_once, a);
    pthread_create(&threads[1], NULL, instantiate_at_once, b);
    pthread_join(threads[0], NULL);
    pthread_join(threads[1], NULL);
    pthread_barrier_destroy(&together);
}

/* The process's private memory in bytes (Windows: PrivateUsage; Linux: resident set). */
static size_t process_memory(void)
{
#ifdef _WIN32
    PROCESS_MEMORY_COUNTERS_EX counters;
    if (!GetProcessMemoryInfo(GetCurrentProcess(), (PROCESS_MEMORY_COUNTERS *)&counters, sizeof counters)) return 0;
    return counters.PrivateUsage;
#else
    long pages = 0, resident = 0;
    FILE *statm = fopen("/proc/self/statm", "r");
    if (statm == NULL) return 0;
    if (fscanf(statm, "%ld %ld", &pages, &resident) != 2) resident = 0;
    fclose(statm);
    return (size_t)resident * 4096;
#endif
}

/* N instantiate -> setup -> initialize -> step -> free cycles of one FMU; prints "memory K BYTES" after cycles
 * 1, 10, 50, 100, ... and N (the caller judges the growth) */
static void cycles(Fmu *f, long n)
{
    for (long k = 1; k <= n; k++) {
        if (f->version == 3) {
            fmi3Instance c = f->v3.InstantiateCoSimulation(f->name, f->guid, f->resources, fmi3False, fmi3False, fmi3False,
                                                           fmi3False, NULL, 0, f, log3, NULL);
            if (c == NULL) die("cycles: instantiation failed of", f->name);
            if (f->v3.EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3False, 0.0) > fmi3Warning
                || f->v3.ExitInitializationMode(c) > fmi3Warning) die("cycles: initialization failed of", f->name);
            fmi3Boolean event, terminate, early;
            fmi3Float64 reached;
            f->v3.DoStep(c, 0.0, 1e-3, fmi3True, &event, &terminate, &early, &reached);
            f->v3.FreeInstance(c);
        } else {
            fmi2Component c = f->Instantiate(f->name, fmi2CoSimulation, f->guid, f->resources, &callbacks, fmi2False,
                                             fmi2False);
            if (c == NULL) die("cycles: instantiation failed of", f->name);
            if (f->SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) > fmi2Warning
                || f->EnterInitializationMode(c) > fmi2Warning || f->ExitInitializationMode(c) > fmi2Warning)
                die("cycles: initialization failed of", f->name);
            f->DoStep(c, 0.0, 1e-3, fmi2True);
            f->FreeInstance(c);
        }
        if (k == 1 || k == 10 || k % 50 == 0 || k == n) printf("memory %ld %zu\n", k, process_memory());
    }
}

int main(int argc, char **argv)
{
    char line[16384];
    if (argc != 2) die("usage: importer SCRIPT", NULL);
    FILE *script = fopen(argv[1], "r");
    if (script == NULL) die("cannot read", argv[1]);
    while (fgets(line, sizeof line, script)) {
        char *tokens[256];
        int n = 0;
        for (char *token = strtok(line, " \t\r\n"); token && n < 256; token = strtok(NULL, " \t\r\n")) tokens[n++] = token;
        if (n == 0 || tokens[0][0] == '#') continue;
        if (!strcmp(tokens[0], "fmu") && n == 5) {
            Fmu *f = &fmus[count++];
            snprintf(f->name, sizeof f->name, "%s", tokens[1]);
            snprintf(f->guid, sizeof f->guid, "%s", tokens[4]);
            load(f, decoded(tokens[2]), tokens[3]);
        } else if (!strcmp(tokens[0], "fmu3") && n == 5) {
            Fmu *f = &fmus[count++];
            snprintf(f->name, sizeof f->name, "%s", tokens[1]);
            snprintf(f->guid, sizeof f->guid, "%s", tokens[4]);
            load3(f, decoded(tokens[2]), tokens[3]);
        } else if (!strcmp(tokens[0], "output3") && n == 4) {
            Fmu *f = find(tokens[1]);
            f->output_array_vr[f->output_arrays++] = (fmi3ValueReference)atol(tokens[2]);
            for (int k = atoi(tokens[3]); k > 0; k--) f->output_index[f->outputs++] = total_outputs++;
        } else if (!strcmp(tokens[0], "array3") && n == 4) {
            Fmu *f = find(tokens[1]);
            int a = f->arrays++;
            f->array_vr[a] = (fmi3ValueReference)atol(tokens[2]);
            f->array_size[a] = atoi(tokens[3]);
            f->array_offset[a] = a ? f->array_offset[a - 1] + f->array_size[a - 1] : 0;
        } else if (!strcmp(tokens[0], "input3") && n == 5) {
            Fmu *f = find(tokens[1]);
            int a = 0;
            while (a < f->arrays && f->array_vr[a] != (fmi3ValueReference)atol(tokens[2])) a++;
            if (a == f->arrays) die("input3 before array3 of", tokens[2]);
            f->input_position[f->inputs] = f->array_offset[a] + atoi(tokens[3]);
            f->input_source[f->inputs++] = atoi(tokens[4]);
        } else if (!strcmp(tokens[0], "start3") && n == 7) {
            Fmu *f = find(tokens[1]);
            f->start_integer[f->starts] = !strcmp(tokens[2], "integer");
            f->start_vr[f->starts] = (fmi2ValueReference)atol(tokens[3]);
            f->start_size[f->starts] = atoi(tokens[4]);
            f->start_index[f->starts] = atoi(tokens[5]);
            f->start_value[f->starts++] = strtod(tokens[6], NULL);
        } else if (!strcmp(tokens[0], "output") && n == 3) {
            Fmu *f = find(tokens[1]);
            f->output_vr[f->outputs] = (fmi2ValueReference)atol(tokens[2]);
            f->output_index[f->outputs++] = total_outputs++;
        } else if (!strcmp(tokens[0], "input") && n == 4) {
            Fmu *f = find(tokens[1]);
            f->input_vr[f->inputs] = (fmi2ValueReference)atol(tokens[2]);
            f->input_source[f->inputs++] = atoi(tokens[3]);
        } else if (!strcmp(tokens[0], "feedthrough") && n == 2) {
            find(tokens[1])->feedthrough = 1;
        } else if (!strcmp(tokens[0], "start") && n == 5) {
            Fmu *f = find(tokens[1]);
            f->start_integer[f->starts] = !strcmp(tokens[2], "integer");
            f->start_vr[f->starts] = (fmi2ValueReference)atol(tokens[3]);
            f->start_value[f->starts++] = strtod(tokens[4], NULL);
        } else if (!strcmp(tokens[0], "cosim") && n == 7 && !strcmp(tokens[1], "jacobi")) {
            cosim(!strcmp(tokens[2], "linear"), strtod(tokens[3], NULL), strtod(tokens[4], NULL),
                  strtod(tokens[5], NULL), decoded(tokens[6]));
        } else if (!strcmp(tokens[0], "calls") && n >= 7) {
            calls(tokens[1], find(tokens[2]), atol(tokens[3]), atol(tokens[4]), atol(tokens[5]), tokens + 6, n - 6);
        } else if (!strcmp(tokens[0], "clear") && n == 1) {
            memset(fmus, 0, sizeof fmus);
            count = total_outputs = 0;
        } else if (!strcmp(tokens[0], "abuse") && n >= 4) {
            abuse(tokens[1], find(tokens[2]), tokens[3], tokens + 4, n - 4);
        } else if (!strcmp(tokens[0], "parallel") && n == 3) {
            parallel(find(tokens[1]), find(tokens[2]));
        } else if (!strcmp(tokens[0], "cycles") && n == 3) {
            cycles(find(tokens[1]), atol(tokens[2]));
        } else if (!strcmp(tokens[0], "bench") && n == 5) {
            bench(find(tokens[1]), atol(tokens[2]), atol(tokens[3]), atol(tokens[4]));
        } else {
            die("cannot read the command", tokens[0]);
        }
        fflush(stdout);
    }
    fclose(script);
    return 0;
}
