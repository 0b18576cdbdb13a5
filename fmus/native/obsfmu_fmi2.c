/*
 * obsfmu's FMI 2.0 co-simulation binary: forwards every FMI call to the
 * generic Python slave (fmus/slave.py, a pythonfmu Fmi2Slave) of the FMU.
 *
 * Why not pythonfmu's stock binary: it refuses fmi2SetRealInputDerivatives
 * ("FMI function not supported"), turns every Python exception into
 * fmi2Fatal, and its instantiation releases a borrowed reference.  This file
 * implements the same contract with:
 *   - fmi2SetRealInputDerivatives (canInterpolateInputs = true),
 *   - fmi2Get/Set/Free/(De)SerializeFMUstate through the slave's methods,
 *   - a Python exception -> fmi2Error (logged with its message), never fatal,
 *   - do_step() returning False -> fmi2Discard.
 *
 * The FMU runs inside a Python host (fmpy, libcosimpy, ...): the interpreter
 * of the host process executes the slave.  Every entry point takes the GIL.
 *
 * Python side (methods of the slave instance):
 *   setup_experiment(start, stop|None, tolerance|None), enter_initialization_mode(),
 *   exit_initialization_mode(), terminate(), do_step(t, h) -> bool,
 *   get_real/get_integer/get_boolean/get_string(vrs) -> list,
 *   set_real/set_integer/set_boolean/set_string(vrs, values),
 *   set_real_input_derivatives(vrs, orders, values),
 *   get_fmu_state() -> obj, set_fmu_state(obj),
 *   serialize_fmu_state(obj) -> bytes, deserialize_fmu_state(bytes) -> obj,
 *   log_queue: list of messages with .status, .category, .msg (drained after each call).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

typedef struct {
    PyObject *slave_class;
    PyObject *instance;
    PyObject *strings; /* keeps the strings returned by fmi2GetString alive */
    fmi2CallbackFunctions callbacks;
    char *name;
    char *resources;
    int visible;
    int logging_on;
} Component;

/* ------------------------------------------------------------------ logging */

/* The message is passed as the format string with every '%' doubled and no variadic
 * arguments: correct for importers that format it (printf-style) and readable for those that
 * cannot read variadic arguments (fmpy without its logger proxy). */
static void emit(const fmi2CallbackFunctions *callbacks, fmi2ComponentEnvironment environment,
                 const char *name, fmi2Status status, const char *category, const char *message)
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
    callbacks->logger(environment, name, status, category, escaped);
    free(escaped);
}

static void log_message(Component *c, fmi2Status status, const char *category, const char *message)
{
    if (status == fmi2OK && !c->logging_on) {
        return;
    }
    emit(&c->callbacks, c->callbacks.componentEnvironment, c->name, status, category, message);
}

static const char *category_of(fmi2Status status)
{
    switch (status) {
    case fmi2Warning: return "logStatusWarning";
    case fmi2Discard: return "logStatusDiscard";
    case fmi2Error: return "logStatusError";
    case fmi2Fatal: return "logStatusFatal";
    default: return "logAll";
    }
}

/* Forward the slave's queued log messages to the importer; returns the worst status. */
static fmi2Status drain_log(Component *c)
{
    fmi2Status worst = fmi2OK;
    PyObject *queue = PyObject_GetAttrString(c->instance, "log_queue");
    if (queue == NULL || !PyList_Check(queue)) {
        PyErr_Clear();
        Py_XDECREF(queue);
        return worst;
    }
    Py_ssize_t size = PyList_Size(queue);
    for (Py_ssize_t i = 0; i < size; i++) {
        PyObject *item = PyList_GetItem(queue, i); /* borrowed */
        PyObject *status = PyObject_GetAttrString(item, "status");
        PyObject *category = PyObject_GetAttrString(item, "category");
        PyObject *msg = PyObject_GetAttrString(item, "msg");
        long level = status ? PyLong_AsLong(status) : 0;
        const char *category_text = (category && PyUnicode_Check(category)) ? PyUnicode_AsUTF8(category) : NULL;
        const char *msg_text = (msg && PyUnicode_Check(msg)) ? PyUnicode_AsUTF8(msg) : "";
        if (level < fmi2OK || level > fmi2Fatal) level = fmi2OK;
        log_message(c, (fmi2Status)level, category_text ? category_text : category_of((fmi2Status)level),
                    msg_text ? msg_text : "");
        if (level > worst && level <= fmi2Warning) worst = (fmi2Status)level;
        Py_XDECREF(status);
        Py_XDECREF(category);
        Py_XDECREF(msg);
        PyErr_Clear();
    }
    PyList_SetSlice(queue, 0, size, NULL);
    Py_DECREF(queue);
    return worst;
}

/* Log the pending Python exception as fmi2Error and clear it. */
static fmi2Status python_error(Component *c, const char *where)
{
    PyObject *type, *value, *traceback;
    char message[2048];
    PyErr_Fetch(&type, &value, &traceback);
    PyErr_NormalizeException(&type, &value, &traceback);
    const char *type_name = type ? ((PyTypeObject *)type)->tp_name : "error";
    PyObject *text = value ? PyObject_Str(value) : NULL;
    const char *detail = text ? PyUnicode_AsUTF8(text) : "unknown error";
    snprintf(message, sizeof message, "%s: %s: %s", where, type_name, detail ? detail : "");
    Py_XDECREF(text);
    Py_XDECREF(type);
    Py_XDECREF(value);
    Py_XDECREF(traceback);
    PyErr_Clear();
    if (c->instance != NULL) drain_log(c);
    log_message(c, fmi2Error, "logStatusError", message);
    return fmi2Error;
}

/* ------------------------------------------------------------------ helpers */

static PyObject *reference_list(const fmi2ValueReference vr[], size_t nvr)
{
    PyObject *list = PyList_New((Py_ssize_t)nvr);
    for (size_t i = 0; list && i < nvr; i++) {
        PyList_SET_ITEM(list, (Py_ssize_t)i, PyLong_FromUnsignedLong(vr[i]));
    }
    return list;
}

/* Call slave.<method>(*args); steals args; result in *out (may be NULL). */
static fmi2Status call(Component *c, const char *method, PyObject *args, PyObject **out)
{
    if (out) *out = NULL;
    if (args == NULL) return python_error(c, method);
    PyObject *function = PyObject_GetAttrString(c->instance, method);
    if (function == NULL) {
        Py_DECREF(args);
        return python_error(c, method);
    }
    PyObject *result = PyObject_CallObject(function, args);
    Py_DECREF(function);
    Py_DECREF(args);
    if (result == NULL) return python_error(c, method);
    fmi2Status status = drain_log(c);
    if (out) *out = result; else Py_DECREF(result);
    return status;
}

#define WITH_GIL(body)                                  \
    PyGILState_STATE gil_ = PyGILState_Ensure();        \
    fmi2Status status_ = fmi2OK;                        \
    body;                                               \
    PyGILState_Release(gil_);                           \
    return status_;

#define COMPONENT Component *c = (Component *)component; if (c == NULL) return fmi2Error;

static char *copy_string(const char *text)
{
    size_t n = strlen(text) + 1;
    char *copy = malloc(n);
    if (copy) memcpy(copy, text, n);
    return copy;
}

static int hex_value(char digit)
{
    if (digit >= '0' && digit <= '9') return digit - '0';
    if (digit >= 'a' && digit <= 'f') return digit - 'a' + 10;
    if (digit >= 'A' && digit <= 'F') return digit - 'A' + 10;
    return -1;
}

/* file:///a%20b/resources, file:/a/resources or a plain path -> /a b/resources */
static char *resource_path(const char *uri)
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
        if (path[i] == '%' && hex_value(path[i + 1]) >= 0 && hex_value(path[i + 2]) >= 0) {
            decoded[j++] = (char)(hex_value(path[i + 1]) * 16 + hex_value(path[i + 2]));
            i += 2;
        } else {
            decoded[j++] = path[i];
        }
    }
    while (j > 1 && decoded[j - 1] == '/') j--;
    decoded[j] = '\0';
    return decoded;
}

static PyObject *create_instance(Component *c)
{
    PyObject *kwargs = Py_BuildValue("{s:s,s:s,s:O,s:O}", "instance_name", c->name, "resources", c->resources,
                                     "visible", c->visible ? Py_True : Py_False, "logger", Py_None);
    if (kwargs == NULL) return NULL;
    PyObject *args = PyTuple_New(0);
    PyObject *instance = args ? PyObject_Call(c->slave_class, args, kwargs) : NULL;
    Py_XDECREF(args);
    Py_DECREF(kwargs);
    return instance;
}

/* Import resources/<slavemodule>.py and return its class of the same name. */
static PyObject *slave_class(const char *resources, char *error, size_t error_size)
{
    char file_name[4096];
    char module_name[256] = {0};
    snprintf(file_name, sizeof file_name, "%s/slavemodule.txt", resources);
    FILE *file = fopen(file_name, "r");
    if (file == NULL || fgets(module_name, sizeof module_name, file) == NULL) {
        if (file) fclose(file);
        snprintf(error, error_size, "cannot read %s", file_name);
        return NULL;
    }
    fclose(file);
    module_name[strcspn(module_name, "\r\n ")] = '\0';

    PyObject *sys_path = PySys_GetObject("path"); /* borrowed */
    PyObject *entry = PyUnicode_FromString(resources);
    if (sys_path && entry && PySequence_Contains(sys_path, entry) == 0) {
        PyList_Insert(sys_path, 0, entry);
    }
    Py_XDECREF(entry);
    PyObject *module = PyImport_ImportModule(module_name);
    if (module == NULL) {
        snprintf(error, error_size, "cannot import the slave module %s", module_name);
        return NULL;
    }
    PyObject *cls = PyObject_GetAttrString(module, module_name);
    Py_DECREF(module);
    if (cls == NULL) snprintf(error, error_size, "module %s has no class %s", module_name, module_name);
    return cls;
}

static void free_component(Component *c)
{
    if (c == NULL) return;
    Py_XDECREF(c->instance);
    Py_XDECREF(c->slave_class);
    Py_XDECREF(c->strings);
    free(c->name);
    free(c->resources);
    free(c);
}

/* ------------------------------------------------------------------ FMI API */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn)
{
    (void)fmuGUID;
    const char *name = instanceName ? instanceName : "";
    if (fmuType != fmi2CoSimulation) {
        emit(functions, functions ? functions->componentEnvironment : NULL, name, fmi2Error, "logStatusError",
             "this FMU supports co-simulation only");
        return NULL;
    }
    if (dlsym(RTLD_DEFAULT, "Py_IsInitialized") == NULL || !Py_IsInitialized()) {
        emit(functions, functions ? functions->componentEnvironment : NULL, name, fmi2Error, "logStatusError",
             "this FMU runs Python: load it from a Python-based importer (fmpy, libcosimpy, ...)");
        return NULL;
    }
    if (fmuResourceLocation == NULL) {
        emit(functions, functions ? functions->componentEnvironment : NULL, name, fmi2Error, "logStatusError",
             "fmuResourceLocation is required");
        return NULL;
    }
    Component *c = calloc(1, sizeof(Component));
    if (c == NULL) return NULL;
    if (functions) c->callbacks = *functions;
    c->name = copy_string(name);
    c->resources = resource_path(fmuResourceLocation);
    c->visible = visible;
    c->logging_on = loggingOn;
    if (c->name == NULL || c->resources == NULL) {
        free_component(c);
        return NULL;
    }

    PyGILState_STATE gil = PyGILState_Ensure();
    char error[512] = {0};
    c->slave_class = slave_class(c->resources, error, sizeof error);
    if (c->slave_class != NULL) c->instance = create_instance(c);
    if (c->instance == NULL) {
        if (PyErr_Occurred()) {
            python_error(c, error[0] ? error : "fmi2Instantiate");
        } else {
            log_message(c, fmi2Error, "logStatusError", error);
        }
        free_component(c);
        PyGILState_Release(gil);
        return NULL;
    }
    drain_log(c);
    PyGILState_Release(gil);
    return c;
}

void fmi2FreeInstance(fmi2Component component)
{
    Component *c = (Component *)component;
    if (c == NULL) return;
    PyGILState_STATE gil = PyGILState_Ensure();
    free_component(c);
    PyGILState_Release(gil);
}

fmi2Status fmi2SetDebugLogging(fmi2Component component, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[])
{
    (void)nCategories;
    (void)categories;
    COMPONENT
    c->logging_on = loggingOn;
    return fmi2OK;
}

fmi2Status fmi2SetupExperiment(fmi2Component component, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    COMPONENT
    WITH_GIL({
        PyObject *tol = toleranceDefined ? PyFloat_FromDouble(tolerance) : (Py_INCREF(Py_None), Py_None);
        PyObject *stop = stopTimeDefined ? PyFloat_FromDouble(stopTime) : (Py_INCREF(Py_None), Py_None);
        status_ = call(c, "setup_experiment", Py_BuildValue("(dNN)", startTime, stop, tol), NULL);
    })
}

#define SIMPLE_CALL(function, method)                                   \
    fmi2Status function(fmi2Component component)                        \
    {                                                                   \
        COMPONENT                                                       \
        WITH_GIL(status_ = call(c, method, PyTuple_New(0), NULL))       \
    }

SIMPLE_CALL(fmi2EnterInitializationMode, "enter_initialization_mode")
SIMPLE_CALL(fmi2ExitInitializationMode, "exit_initialization_mode")
SIMPLE_CALL(fmi2Terminate, "terminate")

fmi2Status fmi2Reset(fmi2Component component)
{
    COMPONENT
    WITH_GIL({
        PyObject *fresh = create_instance(c);
        if (fresh == NULL) {
            status_ = python_error(c, "fmi2Reset");
        } else {
            Py_DECREF(c->instance);
            c->instance = fresh;
            drain_log(c);
        }
    })
}

/* ---- getters */

static fmi2Status get_values(Component *c, const char *method, const fmi2ValueReference vr[], size_t nvr,
                             PyObject **result)
{
    fmi2Status status = call(c, method, Py_BuildValue("(N)", reference_list(vr, nvr)), result);
    if (status > fmi2Warning) return status;
    if (!PyList_Check(*result) || (size_t)PyList_Size(*result) != nvr) {
        Py_XDECREF(*result);
        *result = NULL;
        log_message(c, fmi2Error, "logStatusError", "slave returned a list of the wrong length");
        return fmi2Error;
    }
    return status;
}

fmi2Status fmi2GetReal(fmi2Component component, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    COMPONENT
    WITH_GIL({
        PyObject *values = NULL;
        status_ = get_values(c, "get_real", vr, nvr, &values);
        for (size_t i = 0; values && i < nvr; i++) value[i] = PyFloat_AsDouble(PyList_GET_ITEM(values, i));
        Py_XDECREF(values);
        if (PyErr_Occurred()) status_ = python_error(c, "fmi2GetReal");
    })
}

fmi2Status fmi2GetInteger(fmi2Component component, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[])
{
    COMPONENT
    WITH_GIL({
        PyObject *values = NULL;
        status_ = get_values(c, "get_integer", vr, nvr, &values);
        for (size_t i = 0; values && i < nvr; i++) value[i] = (fmi2Integer)PyLong_AsLong(PyList_GET_ITEM(values, i));
        Py_XDECREF(values);
        if (PyErr_Occurred()) status_ = python_error(c, "fmi2GetInteger");
    })
}

fmi2Status fmi2GetBoolean(fmi2Component component, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[])
{
    COMPONENT
    WITH_GIL({
        PyObject *values = NULL;
        status_ = get_values(c, "get_boolean", vr, nvr, &values);
        for (size_t i = 0; values && i < nvr; i++) value[i] = PyObject_IsTrue(PyList_GET_ITEM(values, i)) == 1;
        Py_XDECREF(values);
    })
}

fmi2Status fmi2GetString(fmi2Component component, const fmi2ValueReference vr[], size_t nvr, fmi2String value[])
{
    COMPONENT
    WITH_GIL({
        PyObject *values = NULL;
        status_ = get_values(c, "get_string", vr, nvr, &values);
        if (values) {
            Py_XDECREF(c->strings);
            c->strings = values; /* keeps the UTF-8 buffers alive until the next call */
            for (size_t i = 0; i < nvr; i++) {
                const char *text = PyUnicode_AsUTF8(PyList_GET_ITEM(values, i));
                value[i] = text ? text : "";
            }
            PyErr_Clear();
        }
    })
}

/* ---- setters */

static fmi2Status set_values(Component *c, const char *method, const fmi2ValueReference vr[], size_t nvr,
                             PyObject *values)
{
    if (values == NULL) return python_error(c, method);
    return call(c, method, Py_BuildValue("(NN)", reference_list(vr, nvr), values), NULL);
}

fmi2Status fmi2SetReal(fmi2Component component, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[])
{
    COMPONENT
    WITH_GIL({
        PyObject *values = PyList_New((Py_ssize_t)nvr);
        for (size_t i = 0; values && i < nvr; i++) PyList_SET_ITEM(values, (Py_ssize_t)i, PyFloat_FromDouble(value[i]));
        status_ = set_values(c, "set_real", vr, nvr, values);
    })
}

fmi2Status fmi2SetInteger(fmi2Component component, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Integer value[])
{
    COMPONENT
    WITH_GIL({
        PyObject *values = PyList_New((Py_ssize_t)nvr);
        for (size_t i = 0; values && i < nvr; i++) PyList_SET_ITEM(values, (Py_ssize_t)i, PyLong_FromLong(value[i]));
        status_ = set_values(c, "set_integer", vr, nvr, values);
    })
}

fmi2Status fmi2SetBoolean(fmi2Component component, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Boolean value[])
{
    COMPONENT
    WITH_GIL({
        PyObject *values = PyList_New((Py_ssize_t)nvr);
        for (size_t i = 0; values && i < nvr; i++) PyList_SET_ITEM(values, (Py_ssize_t)i, PyBool_FromLong(value[i]));
        status_ = set_values(c, "set_boolean", vr, nvr, values);
    })
}

fmi2Status fmi2SetString(fmi2Component component, const fmi2ValueReference vr[], size_t nvr,
                         const fmi2String value[])
{
    COMPONENT
    WITH_GIL({
        PyObject *values = PyList_New((Py_ssize_t)nvr);
        for (size_t i = 0; values && i < nvr; i++)
            PyList_SET_ITEM(values, (Py_ssize_t)i, PyUnicode_FromString(value[i] ? value[i] : ""));
        status_ = set_values(c, "set_string", vr, nvr, values);
    })
}

/* ---- FMU state */

fmi2Status fmi2GetFMUstate(fmi2Component component, fmi2FMUstate *state)
{
    COMPONENT
    WITH_GIL({
        PyObject *snapshot = NULL;
        status_ = call(c, "get_fmu_state", PyTuple_New(0), &snapshot);
        if (snapshot) {
            Py_XDECREF((PyObject *)*state);
            *state = snapshot;
        }
    })
}

fmi2Status fmi2SetFMUstate(fmi2Component component, fmi2FMUstate state)
{
    COMPONENT
    if (state == NULL) return fmi2Error;
    WITH_GIL(status_ = call(c, "set_fmu_state", Py_BuildValue("(O)", (PyObject *)state), NULL))
}

fmi2Status fmi2FreeFMUstate(fmi2Component component, fmi2FMUstate *state)
{
    COMPONENT
    if (state == NULL || *state == NULL) return fmi2OK;
    WITH_GIL({
        Py_DECREF((PyObject *)*state);
        *state = NULL;
    })
}

static fmi2Status serialized(Component *c, fmi2FMUstate state, PyObject **bytes)
{
    fmi2Status status = call(c, "serialize_fmu_state", Py_BuildValue("(O)", (PyObject *)state), bytes);
    if (*bytes && !PyBytes_Check(*bytes)) {
        Py_DECREF(*bytes);
        *bytes = NULL;
        log_message(c, fmi2Error, "logStatusError", "serialize_fmu_state did not return bytes");
        return fmi2Error;
    }
    return status;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component component, fmi2FMUstate state, size_t *size)
{
    COMPONENT
    if (state == NULL) return fmi2Error;
    WITH_GIL({
        PyObject *bytes = NULL;
        status_ = serialized(c, state, &bytes);
        if (bytes) *size = (size_t)PyBytes_GET_SIZE(bytes);
        Py_XDECREF(bytes);
    })
}

fmi2Status fmi2SerializeFMUstate(fmi2Component component, fmi2FMUstate state, fmi2Byte buffer[], size_t size)
{
    COMPONENT
    if (state == NULL) return fmi2Error;
    WITH_GIL({
        PyObject *bytes = NULL;
        status_ = serialized(c, state, &bytes);
        if (bytes) {
            if ((size_t)PyBytes_GET_SIZE(bytes) > size) {
                log_message(c, fmi2Error, "logStatusError", "fmi2SerializeFMUstate: buffer too small");
                status_ = fmi2Error;
            } else {
                memcpy(buffer, PyBytes_AS_STRING(bytes), (size_t)PyBytes_GET_SIZE(bytes));
            }
            Py_DECREF(bytes);
        }
    })
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component component, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *state)
{
    COMPONENT
    WITH_GIL({
        PyObject *snapshot = NULL;
        status_ = call(c, "deserialize_fmu_state",
                       Py_BuildValue("(N)", PyBytes_FromStringAndSize(serializedState, (Py_ssize_t)size)), &snapshot);
        if (snapshot) {
            Py_XDECREF((PyObject *)*state);
            *state = snapshot;
        }
    })
}

/* ---- derivatives */

fmi2Status fmi2GetDirectionalDerivative(fmi2Component component, const fmi2ValueReference vUnknown_ref[],
                                        size_t nUnknown, const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[])
{
    (void)vUnknown_ref; (void)nUnknown; (void)vKnown_ref; (void)nKnown; (void)dvKnown; (void)dvUnknown;
    COMPONENT
    log_message(c, fmi2Error, "logStatusError", "fmi2GetDirectionalDerivative is not supported");
    return fmi2Error;
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component component, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[])
{
    COMPONENT
    WITH_GIL({
        PyObject *orders = PyList_New((Py_ssize_t)nvr);
        PyObject *values = PyList_New((Py_ssize_t)nvr);
        for (size_t i = 0; orders && values && i < nvr; i++) {
            PyList_SET_ITEM(orders, (Py_ssize_t)i, PyLong_FromLong(order[i]));
            PyList_SET_ITEM(values, (Py_ssize_t)i, PyFloat_FromDouble(value[i]));
        }
        status_ = call(c, "set_real_input_derivatives",
                       Py_BuildValue("(NNN)", reference_list(vr, nvr), orders, values), NULL);
    })
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component component, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[])
{
    (void)vr; (void)nvr; (void)order; (void)value;
    COMPONENT
    log_message(c, fmi2Error, "logStatusError", "fmi2GetRealOutputDerivatives is not supported "
                "(maxOutputDerivativeOrder = 0)");
    return fmi2Error;
}

/* ---- stepping */

fmi2Status fmi2DoStep(fmi2Component component, fmi2Real currentCommunicationPoint,
                      fmi2Real communicationStepSize, fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    (void)noSetFMUStatePriorToCurrentPoint;
    COMPONENT
    WITH_GIL({
        PyObject *result = NULL;
        status_ = call(c, "do_step", Py_BuildValue("(dd)", currentCommunicationPoint, communicationStepSize),
                       &result);
        if (result) {
            if (PyObject_IsTrue(result) != 1) status_ = fmi2Discard;
            Py_DECREF(result);
        }
    })
}

fmi2Status fmi2CancelStep(fmi2Component component)
{
    COMPONENT
    log_message(c, fmi2Error, "logStatusError", "fmi2CancelStep: steps are synchronous, nothing to cancel");
    return fmi2Error;
}

fmi2Status fmi2GetStatus(fmi2Component component, const fmi2StatusKind s, fmi2Status *value)
{
    (void)s; (void)value;
    COMPONENT
    return fmi2Discard;
}

fmi2Status fmi2GetRealStatus(fmi2Component component, const fmi2StatusKind s, fmi2Real *value)
{
    COMPONENT
    if (s != fmi2LastSuccessfulTime) return fmi2Discard;
    WITH_GIL({
        PyObject *time = PyObject_GetAttrString(c->instance, "last_successful_time");
        if (time == NULL) {
            status_ = python_error(c, "fmi2GetRealStatus");
        } else {
            *value = PyFloat_AsDouble(time);
            Py_DECREF(time);
        }
    })
}

fmi2Status fmi2GetIntegerStatus(fmi2Component component, const fmi2StatusKind s, fmi2Integer *value)
{
    (void)s; (void)value;
    COMPONENT
    return fmi2Discard;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component component, const fmi2StatusKind s, fmi2Boolean *value)
{
    COMPONENT
    if (s != fmi2Terminated) return fmi2Discard;
    *value = fmi2False;
    return fmi2OK;
}

fmi2Status fmi2GetStringStatus(fmi2Component component, const fmi2StatusKind s, fmi2String *value)
{
    (void)s; (void)value;
    COMPONENT
    return fmi2Discard;
}
