/*
 * The BRIDGE of an obsfmu FMU: the FMI 2.0 calls -> the generic Python slave (fmus/runtime/slave,
 * a pythonfmu Fmi2Slave), compiled against one Python version's headers.
 *
 * It is loaded by the LOADER (loader.c) with RTLD_LOCAL once libpython's symbols are global
 * (in a Python host, or after the loader has loaded libpython: the recorded one, started by start(),
 * or a standalone FMU's own, started isolated by start_isolated()); it has no NEEDED entry on
 * libpython and exports only obsfmu_bridge(), the function table of obsfmu_native.h.  The
 * loader checks the call sequence (FMI state machine) before anything gets here.
 *
 * What this part guarantees:
 *   - fmi2SetRealInputDerivatives (canInterpolateInputs = true),
 *   - fmi2Get/Set/Free/(De)SerializeFMUstate through the slave's methods,
 *   - status rule: a call returns the worst of its own result and of the levels the slave
 *     logged during the call, capped at fmi2Error (never fmi2Fatal); a Python exception is
 *     fmi2Error with its message logged; do_step() returning False is fmi2Discard,
 *   - refused or failed: an exception of the slave class's `Refused` type means the slave refused
 *     the call and changed nothing; refused() tells the loader so, which then keeps the instance's
 *     state (any other exception, or an error-level message, is a failure: docs/faults.md),
 *   - FMU states hold the loader's fields (ObsfmuMachine): get_fmu_state(loader) stores them,
 *     loader_fields(state) gives them back; the serialized form is the slave's, one format,
 *   - the slave's code is the FMU's own: the bundled package resources/<package>/ (named after
 *     the hash of the bundled code) is imported by obsfmu_bootstrap.py, never via sys.path.
 *
 * Python side (methods of the slave instance):
 *   setup_experiment(start, stop|None, tolerance|None), enter_initialization_mode(),
 *   exit_initialization_mode(), terminate(), do_step(t, h) -> bool,
 *   get_real/get_integer/get_boolean/get_string(vrs) -> list,
 *   set_real/set_integer/set_boolean/set_string(vrs, values),
 *   set_real_input_derivatives(vrs, orders, values), clear_input_derivatives(vrs),
 *   get_real_output_derivatives(vrs, orders) -> list (fmi2GetRealOutputDerivatives),
 *   get_fmu_state(loader={"fmi": 2|3, "state": name}) -> obj, set_fmu_state(obj),
 *   loader_fields(obj) -> (loader dict or None, time, initialized),
 *   serialize_fmu_state(obj) -> bytes, deserialize_fmu_state(bytes) -> obj,
 *   batch_plan(input vrs, slopes: bool, output vrs) -> (values, slopes, outputs) float64 vectors,
 *   step_batched(t, h) -> bool (obsfmuDoStepBatched: the vectors filled and read in place),
 *   log_queue: list of messages with .status, .category, .msg (drained after each call);
 *   kernel_load() -> (layout int64, memory float64) | None | False, kernel_store(), kernel_matrices(h, slot) -> bool
 *   (the compiled step kernel of a linear block or an expression plant, kernel.h: see "the kernel" below);
 *   class attribute Refused: the exception type of refused calls.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include "obsfmu_native.h"
#include "kernel.h"
#ifdef _WIN32
#include "win32_dlfcn.h" /* the FMU's kernel library: dlopen & co. over LoadLibraryExW */
#else
#include <dlfcn.h>
#endif

#ifdef _WIN32
#define OBSFMU_BRIDGE_EXPORT __declspec(dllexport) /* win64: linked to python3X.dll by its name */
#else
#define OBSFMU_BRIDGE_EXPORT __attribute__((visibility("default")))
#endif

/* The buffers of do_step_batched: the slave's vectors of input values, slopes and outputs
 * (slave.batch_plan), written and read in place through the buffer protocol, for the value
 * references they were made for; and the bound method slave.step_batched. */
typedef struct {
    PyObject *step;                 /* NULL: not bound */
    Py_buffer buffers[3];           /* values, slopes, outputs */
    fmi2ValueReference *inputs, *outputs;
    size_t ninputs, noutputs;
    int slopes;
} Batch;

/* The compiled step kernel (kernel.h) of an instance: the slave's image, bound while the calls run in C. */
typedef struct {
    int off;            /* kernels=python in the record, or OBSFMU_KERNELS=python: Python steps */
    int never;          /* the slave has no kernel for this instance (until fmi2Reset) */
    int armed;          /* initialization is over: the slave may hand an image */
    int wanted;         /* ask the slave for an image (it said "not now"; a call has reached Python since) */
    int loaded;         /* the image is bound: inputs, steps and outputs run in C */
    int dirty;          /* the kernel changed the image since it was loaded */
    int announced;      /* the first image was logged (logAll, with logging on) */
    PyObject *memory, *layout;
    Py_buffer views[2]; /* of memory and layout */
    KernelImage image;
    char *path;         /* the FMU's kernel library (record: kernel_library), NULL: none */
    void *library;      /* loaded on first use: the compiled expressions of an expression plant */
} Kernel;

typedef struct {
    PyObject *slave_class;
    PyObject *refusal;  /* slave_class.Refused: the exception of a refused call (NULL: none) */
    PyObject *instance;
    PyObject *strings; /* keeps the strings returned by fmi2GetString alive */
    fmi2CallbackFunctions callbacks;
    char *name;
    char *resources;
    int visible;
    int logging_on;
    int refused;        /* the last call returned fmi2Error because the slave refused it */
    size_t variables;   /* len(slave.vars): the number of its scalar variables */
    Batch batch;        /* obsfmuDoStepBatched's buffers (bound on first use) */
    Kernel kernel;      /* the compiled step kernel, when the slave has one */
} Component;

static void kernel_release(Component *c);

/* ------------------------------------------------------------------ logging */

static void log_message(Component *c, fmi2Status status, const char *category, const char *message)
{
    if (status == fmi2OK && !c->logging_on) return;
    obsfmu_emit(&c->callbacks, c->name, status, category, message);
}

/* Forward the slave's queued log messages to the importer; returns the worst level, capped at
 * fmi2Error. */
static fmi2Status drain_log(Component *c)
{
    fmi2Status worst = fmi2OK;
    static PyObject *name = NULL; /* interned once: this runs after every call */
    if (name == NULL && (name = PyUnicode_InternFromString("log_queue")) == NULL) {
        PyErr_Clear();
        return worst;
    }
    PyObject *queue = PyObject_GetAttr(c->instance, name);
    if (queue == NULL || !PyList_Check(queue)) {
        PyErr_Clear();
        Py_XDECREF(queue);
        return worst;
    }
    Py_ssize_t size = PyList_Size(queue);
    if (size == 0) {
        Py_DECREF(queue);
        return worst;
    }
    for (Py_ssize_t i = 0; i < size; i++) {
        PyObject *item = PyList_GetItem(queue, i); /* borrowed */
        PyObject *status = PyObject_GetAttrString(item, "status");
        PyObject *category = PyObject_GetAttrString(item, "category");
        PyObject *msg = PyObject_GetAttrString(item, "msg");
        long level = status ? PyLong_AsLong(status) : 0;
        const char *category_text = (category && PyUnicode_Check(category)) ? PyUnicode_AsUTF8(category) : NULL;
        const char *msg_text = (msg && PyUnicode_Check(msg)) ? PyUnicode_AsUTF8(msg) : "";
        if (level < fmi2OK || level > fmi2Fatal) level = fmi2Error;
        if (level == fmi2Fatal) level = fmi2Error; /* the slave cannot corrupt other instances */
        log_message(c, (fmi2Status)level, category_text ? category_text : obsfmu_category((fmi2Status)level),
                    msg_text ? msg_text : "");
        if (level > worst) worst = (fmi2Status)level;
        Py_XDECREF(status);
        Py_XDECREF(category);
        Py_XDECREF(msg);
        PyErr_Clear();
    }
    PyList_SetSlice(queue, 0, size, NULL);
    Py_DECREF(queue);
    return worst;
}

/* Log the pending Python exception as fmi2Error and clear it; a refusal (the slave's Refused) is
 * logged with its message alone and marked in c->refused, anything else names the exception type. */
static fmi2Status python_error(Component *c, const char *where)
{
    PyObject *type, *value, *traceback;
    char message[4096];
    PyErr_Fetch(&type, &value, &traceback);
    PyErr_NormalizeException(&type, &value, &traceback);
    c->refused = c->refusal != NULL && type != NULL && PyErr_GivenExceptionMatches(type, c->refusal);
    const char *type_name = type ? ((PyTypeObject *)type)->tp_name : "error";
    PyObject *text = value ? PyObject_Str(value) : NULL;
    const char *detail = text ? PyUnicode_AsUTF8(text) : "unknown error";
    if (c->refused)
        snprintf(message, sizeof message, "%s refused: %s", where, detail ? detail : "");
    else
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

/* every call that reaches Python: the kernel's image written back into the slave first */
#define WITH_GIL(body)                                  \
    PyGILState_STATE gil_ = PyGILState_Ensure();        \
    fmi2Status status_ = fmi2OK;                        \
    kernel_release(c);                                  \
    body;                                               \
    PyGILState_Release(gil_);                           \
    return status_;

/* every entry point: the component, and no refusal yet for this call */
#define COMPONENT Component *c = (Component *)component; if (c == NULL) return fmi2Error; c->refused = 0;

static char *copy_string(const char *text)
{
    size_t n = strlen(text) + 1;
    char *copy = malloc(n);
    if (copy) memcpy(copy, text, n);
    return copy;
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

/* ------------------------------------------------------------------ the slave's test of numbers, in C */

/* Add the squares of the numbers of `item` -- a Python float, or a C-contiguous buffer of float64 or
 * complex128 (a numpy array) -- to *sum.  0: `item` is neither (no Python error is left set). */
static int add_squares(PyObject *item, double *sum)
{
    if (PyFloat_CheckExact(item)) {
        double v = PyFloat_AS_DOUBLE(item);
        *sum += v * v;
        return 1;
    }
    Py_buffer view;
    if (PyObject_GetBuffer(item, &view, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) != 0) {
        PyErr_Clear();
        return 0;
    }
    int known = view.format != NULL && (strcmp(view.format, "d") == 0 || strcmp(view.format, "Zd") == 0);
    if (known) {                                  /* |re + i im|^2 = re^2 + im^2: a complex is two doubles */
        const double *x = view.buf;
        double s = 0.0;
        for (Py_ssize_t i = 0, n = view.len / (Py_ssize_t)sizeof(double); i < n; i++) s += x[i] * x[i];
        *sum += s;
    }
    PyBuffer_Release(&view);
    return known;
}

/* slave.native_within(bound, vector, arrays, previous, floats): True when every number of `vector` (one array,
 * or None), of the arrays of the list `arrays` (or None) less those that are the very object at the same place
 * in `previous` (a list of the same length, or None), and of the list `floats` (or None) is finite and at most
 * `bound` in magnitude, as their sum of squares shows; False when that sum does not show it (a number that is
 * not finite, or large ones), None when an item is of another kind or `previous` of another length.  Only True
 * decides: the caller tests anything else number by number (fmus/runtime/slave/step.py; the same test as
 * observers.state.within_bound, without concatenating the arrays: issue 14). */
static PyObject *native_within(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 5 || !PyFloat_CheckExact(args[0])) {
        PyErr_SetString(PyExc_TypeError, "native_within(bound: float, vector, arrays, previous, floats)");
        return NULL;
    }
    double bound = PyFloat_AS_DOUBLE(args[0]), sum = 0.0;
    PyObject *vector = args[1], *arrays = args[2], *previous = args[3], *floats = args[4];
    if (vector != Py_None && !add_squares(vector, &sum)) Py_RETURN_NONE;
    if (arrays != Py_None) {
        if (!PyList_CheckExact(arrays)) Py_RETURN_NONE;
        Py_ssize_t n = PyList_GET_SIZE(arrays);
        if (previous != Py_None && !PyList_CheckExact(previous)) Py_RETURN_NONE;
        int skip = previous != Py_None && PyList_GET_SIZE(previous) > 0;
        if (skip && PyList_GET_SIZE(previous) != n) Py_RETURN_NONE;
        for (Py_ssize_t i = 0; i < n; i++) {
            PyObject *item = PyList_GET_ITEM(arrays, i);
            if (skip && item == PyList_GET_ITEM(previous, i)) continue;   /* not rebound: tested before */
            if (!add_squares(item, &sum)) Py_RETURN_NONE;
        }
    }
    if (floats != Py_None) {
        if (!PyList_CheckExact(floats)) Py_RETURN_NONE;
        for (Py_ssize_t i = 0, n = PyList_GET_SIZE(floats); i < n; i++)
            if (!add_squares(PyList_GET_ITEM(floats, i), &sum)) Py_RETURN_NONE;
    }
    return PyBool_FromLong(sum <= bound * bound && sum < HUGE_VAL);  /* false for NaN and inf */
}

/* native_within as a Python function, for the slave instance (attribute `native_within`, removed when the
 * instance is freed).  Its method definition is on the heap, never freed: Python reads it when the function
 * object is deallocated, which may be after this library is unloaded (a reference cycle); a static one would
 * be unmapped by then. */
static PyObject *native_within_function(void)
{
    static PyMethodDef *definition = NULL;
    if (definition == NULL) {
        definition = calloc(1, sizeof *definition);
        char *name = copy_string("native_within");
        if (definition == NULL || name == NULL) {
            free(definition);
            free(name);
            definition = NULL;
            return PyErr_NoMemory();
        }
        definition->ml_name = name;
        definition->ml_meth = (PyCFunction)(void (*)(void))native_within;
        definition->ml_flags = METH_FASTCALL;
    }
    return PyCFunction_New(definition, NULL);
}

/* A new slave instance with its native_within (a slave without it still works: it tests in numpy). */
static PyObject *new_instance(Component *c)
{
    PyObject *instance = create_instance(c);
    if (instance == NULL) return NULL;   /* its exception stays set: the caller logs it */
    PyObject *within = native_within_function();
    if (within == NULL || PyObject_SetAttrString(instance, "native_within", within) != 0) PyErr_Clear();
    Py_XDECREF(within);
    return instance;
}

/* Let go of a slave instance, first of its native_within, which points into this library: the instance may
 * live on in a reference cycle after the library is unloaded. */
static void release_instance(PyObject *instance)
{
    if (instance == NULL) return;
    if (PyObject_DelAttrString(instance, "native_within") != 0) PyErr_Clear();
    Py_DECREF(instance);
}

/* The slave class of the FMU, from its own bundled package (resources/obsfmu_bootstrap.py). */
static PyObject *slave_class(Component *c, const char *record)
{
    char package[256], module[256], name[256], bootstrap[4096];
    obsfmu_record_value(record, "package", package, sizeof package);
    obsfmu_record_value(record, "slave_module", module, sizeof module);
    obsfmu_record_value(record, "slave_class", name, sizeof name);
    snprintf(bootstrap, sizeof bootstrap, "%s/obsfmu_bootstrap.py", c->resources);
    PyObject *runpy = PyImport_ImportModule("runpy");
    PyObject *namespace = runpy ? PyObject_CallMethod(runpy, "run_path", "sOs", bootstrap, Py_None, "obsfmu_bootstrap") : NULL;
    PyObject *load = namespace ? PyDict_GetItemString(namespace, "load_slave_class") : NULL; /* borrowed */
    PyObject *cls = load ? PyObject_CallFunction(load, "ssss", c->resources, package, module, name) : NULL;
    if (namespace && load == NULL && !PyErr_Occurred())
        PyErr_Format(PyExc_RuntimeError, "%s defines no load_slave_class", bootstrap);
    Py_XDECREF(namespace);
    Py_XDECREF(runpy);
    return cls;
}

static void drop_batch(Batch *b)
{
    if (b->step != NULL) {
        for (int i = 0; i < 3; i++) PyBuffer_Release(&b->buffers[i]);
        Py_CLEAR(b->step);
    }
    free(b->inputs);
    free(b->outputs);
    memset(b, 0, sizeof *b);
}

/* ------------------------------------------------------------------ the kernel (kernel.h)
 *
 * The calls that run in C -- fmi2SetReal of inputs, fmi2SetRealInputDerivatives, fmi2GetReal of inputs, outputs
 * and parameters, fmi2DoStep and obsfmuDoStepBatched -- take the image of the slave (kernel_load) once after
 * initialization, and keep it while only they are called: no GIL, no Python.  Any other call, and any call the
 * kernel cannot vouch for, writes the image back into the slave (kernel_release -> slave.kernel_store) and is
 * carried out in Python, which may change anything: the image is taken again by the next call that can run in
 * C.  So the slave's state, its FMU states and its refusals are those of the Python path. */

static void kernel_drop(Kernel *k)
{
    if (k->loaded) {
        PyBuffer_Release(&k->views[0]);
        PyBuffer_Release(&k->views[1]);
    }
    Py_CLEAR(k->memory);
    Py_CLEAR(k->layout);
    k->loaded = k->dirty = 0;
}

/* Before a call reaches Python (GIL held): the image back into the slave, and let go. */
static void kernel_release(Component *c)
{
    Kernel *k = &c->kernel;
    if (k->loaded && k->dirty) {
        PyObject *done = PyObject_CallMethod(c->instance, "kernel_store", NULL);
        if (done == NULL) python_error(c, "kernel_store"); /* a bug; the slave keeps its state from before */
        Py_XDECREF(done);
    }
    kernel_drop(k);
    k->wanted = 1;
}

/* The compiled expressions of the image (KK_EXPRESSION, KK_LTV) from the FMU's kernel library; 0 when found. */
static int kernel_functions(Component *c)
{
    Kernel *k = &c->kernel;
    if (k->image.kind == KK_AFFINE) return 0;
    if (k->library == NULL && k->path != NULL) k->library = dlopen(k->path, RTLD_NOW | RTLD_LOCAL);
    if (k->library != NULL) {
        k->image.f = (KernelFunction *)dlsym(k->library, OBSFMU_KERNEL_F);
        k->image.g = (KernelFunction *)dlsym(k->library, OBSFMU_KERNEL_G);
        k->image.l = (KernelFunction *)dlsym(k->library, OBSFMU_KERNEL_L);
        k->image.c = (KernelFunction *)dlsym(k->library, OBSFMU_KERNEL_C);
        k->image.v = (KernelFunction *)dlsym(k->library, OBSFMU_KERNEL_V);
    }
    return k->image.f != NULL && k->image.g != NULL && (k->image.kind != KK_LTV || k->image.l != NULL) &&
                   (k->image.kind != KK_LTV_PLANT || k->image.v != NULL) &&
                   (!kt_c_varies(&k->image) || k->image.c != NULL)
               ? 0
               : -1;
}

/* 1 when the image is bound (taken now if the slave hands one); 0: this call goes to Python. */
static int kernel_ready(Component *c)
{
    Kernel *k = &c->kernel;
    if (k->loaded) return 1;
    if (k->off || k->never || !k->armed || !k->wanted) return 0;
    PyGILState_STATE gil = PyGILState_Ensure();
    PyObject *image = PyObject_CallMethod(c->instance, "kernel_load", NULL);
    k->wanted = 0;
    if (image == NULL) {
        python_error(c, "kernel_load"); /* a bug: logged, and Python steps this instance */
        k->never = 1;
    } else if (image == Py_False) {
        k->never = 1;
    } else if (PyTuple_Check(image) && PyTuple_Size(image) == 2) {
        k->layout = PyTuple_GET_ITEM(image, 0);
        k->memory = PyTuple_GET_ITEM(image, 1);
        Py_INCREF(k->layout);
        Py_INCREF(k->memory);
        int bound = 0;
        if (PyObject_GetBuffer(k->memory, &k->views[0], PyBUF_WRITABLE | PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) == 0) {
            if (PyObject_GetBuffer(k->layout, &k->views[1], PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) == 0) bound = 2;
            else PyBuffer_Release(&k->views[0]);
        }
        PyErr_Clear();
        if (bound == 2 && k->views[0].itemsize == sizeof(double) && k->views[1].itemsize == sizeof(int64_t) &&
            kernel_bind(&k->image, k->views[0].buf, (size_t)k->views[0].len / sizeof(double), k->views[1].buf,
                        (size_t)k->views[1].len / sizeof(int64_t)) == 0 && kernel_functions(c) == 0) {
            k->loaded = 1;
            if (!k->announced) {
                k->announced = 1;
                log_message(c, fmi2OK, "logAll", k->image.kind == KK_AFFINE
                            ? "steps run in the compiled kernel (linear block; OBSFMU_KERNELS=python: in Python)"
                            : k->image.kind == KK_LTV || k->image.kind == KK_LTV_PLANT
                            ? "steps run in the compiled kernel (paper 001's block, its functions compiled to C; "
                              "OBSFMU_KERNELS=python: in Python)"
                            : "steps run in the compiled kernel (expressions compiled to C; OBSFMU_KERNELS=python: "
                              "in Python)");
            }
        } else {
            if (bound == 2) {
                PyBuffer_Release(&k->views[0]);
                PyBuffer_Release(&k->views[1]);
            }
            Py_CLEAR(k->memory);
            Py_CLEAR(k->layout);
            log_message(c, fmi2Warning, "logStatusWarning", "the step kernel's image does not fit this bridge, or "
                        "its kernel library is missing: the FMU steps in Python (rebuild it with this obsfmu)");
            k->never = 1;
        }
    }
    Py_XDECREF(image);
    PyGILState_Release(gil);
    return k->loaded;
}

/* The kernel's step (asking the slave for the matrices of a new step size h); 1 when taken in C. */
static int kernel_advance(Component *c, double t, double h)
{
    KernelImage *image = &c->kernel.image;
    int taken = kernel_step(image, t, h);
    if (taken < 0) {
        PyGILState_STATE gil = PyGILState_Ensure();
        PyObject *done = PyObject_CallMethod(c->instance, "kernel_matrices", "di", h, image->slot);
        if (done == NULL) PyErr_Clear(); /* a bug in the slave: the Python path steps (and says what is wrong) */
        if (done == Py_True) taken = kernel_step(image, t, h);
        Py_XDECREF(done);
        PyGILState_Release(gil);
    }
    if (taken > 0) c->kernel.dirty = 1;
    return taken > 0;
}

static void free_component(Component *c)
{
    if (c == NULL) return;
    kernel_drop(&c->kernel);
    if (c->kernel.library != NULL) dlclose(c->kernel.library);
    free(c->kernel.path);
    drop_batch(&c->batch);
    release_instance(c->instance);
    Py_XDECREF(c->refusal);
    Py_XDECREF(c->slave_class);
    Py_XDECREF(c->strings);
    free(c->name);
    free(c->resources);
    free(c);
}

/* ------------------------------------------------------------------ start-up */

/* Start the interpreter of `config` (cleared here) unless `status` is an exception already; 0 on success. */
static int start_from(PyConfig *config, PyStatus status, const char *where, char *message, size_t size)
{
    config->install_signal_handlers = 0; /* the host owns the signals */
    config->parse_argv = 0;
    config->use_environment = 0;         /* PYTHONHOME/PYTHONPATH of the host are not ours */
    config->configure_c_stdio = 0;
    config->pathconfig_warnings = 0;     /* failures are reported through the FMI logger */
    if (!PyStatus_Exception(status)) status = Py_InitializeFromConfig(config);
    PyConfig_Clear(config);
    if (PyStatus_Exception(status)) {
        snprintf(message, size, "starting Python from %s failed: %s%s%s", where, status.func ? status.func : "",
                 status.func ? ": " : "", status.err_msg ? status.err_msg : "unknown error");
        return -1;
    }
    PyEval_SaveThread(); /* every call takes the GIL with PyGILState_Ensure; never finalized */
    return 0;
}

static int start(const char *program, char *message, size_t size)
{
    PyConfig config;
    PyConfig_InitPythonConfig(&config);
    return start_from(&config, PyConfig_SetBytesString(&config, &config.program_name, program), program, message,
                      size);
}

/* Append <home>/<folder> of every folder of the ':'-separated `search` to the module search path. */
static PyStatus search_path(PyConfig *config, const char *home, const char *search)
{
    char path[8192];
    PyStatus status = PyStatus_Ok();
    for (const char *folder = search; *folder && !PyStatus_Exception(status);) {
        size_t length = strcspn(folder, ":");
        snprintf(path, sizeof path, "%s/%.*s", home, (int)length, folder);
        wchar_t *wide = Py_DecodeLocale(path, NULL);
        status = wide ? PyWideStringList_Append(&config->module_search_paths, wide) : PyStatus_NoMemory();
        PyMem_RawFree(wide);
        folder += length + (folder[length] == ':');
    }
    config->module_search_paths_set = 1;
    return status;
}

static int start_isolated(const char *home, const char *search, char *message, size_t size)
{
    PyPreConfig preconfig;
    PyPreConfig_InitIsolatedConfig(&preconfig);
    preconfig.utf8_mode = 1;             /* the same encodings whatever the host's locale */
    PyStatus status = Py_PreInitialize(&preconfig);
    if (PyStatus_Exception(status)) {
        snprintf(message, size, "starting the Python of %s failed: %s", home, status.err_msg ? status.err_msg : "");
        return -1;
    }
    PyConfig config;
    PyConfig_InitIsolatedConfig(&config); /* no user site, no PYTHON* variables, no current directory */
    config.site_import = 0;               /* the search path is the runtime's, nothing to add */
    config.write_bytecode = 0;            /* the FMU may be read-only: its modules are compiled already */
    status = PyConfig_SetBytesString(&config, &config.home, home);
    if (!PyStatus_Exception(status)) status = search_path(&config, home, search);
    return start_from(&config, status, home, message, size);
}

/* ------------------------------------------------------------------ FMI API */

static fmi2Component instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                                 fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                                 fmi2Boolean visible, fmi2Boolean loggingOn)
{
    (void)fmuType;
    (void)fmuGUID; /* checked by the loader */
    Component *c = calloc(1, sizeof(Component));
    if (c == NULL) return NULL;
    if (functions) c->callbacks = *functions;
    c->name = copy_string(instanceName ? instanceName : "");
    c->resources = obsfmu_resource_path(fmuResourceLocation);
    c->visible = visible;
    c->logging_on = loggingOn;
    char *record = c->resources ? obsfmu_read_record(c->resources) : NULL;
    char kernels[32];
    const char *wish = getenv("OBSFMU_KERNELS");
    c->kernel.off = (wish && strcmp(wish, "python") == 0) ||
                    (record && strcmp(obsfmu_record_value(record, "kernels", kernels, sizeof kernels), "python") == 0);
    char library[512];
    if (record && c->resources && obsfmu_record_value(record, "kernel_library", library, sizeof library)[0]) {
        size_t size = strlen(c->resources) + strlen(library) + 8;   /* <resources>/../<binaries/.../x_kernel.so> */
        c->kernel.path = malloc(size);
        if (c->kernel.path) snprintf(c->kernel.path, size, "%s/../%s", c->resources, library);
    }
    if (c->name == NULL || record == NULL) {
        free(record);
        free_component(c);
        return NULL;
    }

    PyGILState_STATE gil = PyGILState_Ensure();
    c->slave_class = slave_class(c, record);
    if (c->slave_class != NULL) {
        c->refusal = PyObject_GetAttrString(c->slave_class, "Refused");
        if (c->refusal == NULL || !PyExceptionClass_Check(c->refusal)) { /* a slave without refusals */
            PyErr_Clear();
            Py_CLEAR(c->refusal);
        }
        c->instance = new_instance(c);
    }
    PyObject *vars = c->instance ? PyObject_GetAttrString(c->instance, "vars") : NULL;
    Py_ssize_t variables = vars ? PyObject_Size(vars) : -1;
    Py_XDECREF(vars);
    if (c->instance == NULL || variables < 0) {
        python_error(c, "fmi2Instantiate");
        free_component(c);
        c = NULL;
    } else {
        c->variables = (size_t)variables;
        drain_log(c);
    }
    PyGILState_Release(gil);
    free(record);
    return c;
}

static void free_instance(fmi2Component component)
{
    Component *c = (Component *)component;
    if (c == NULL) return;
    PyGILState_STATE gil = PyGILState_Ensure();
    free_component(c);
    PyGILState_Release(gil);
}

static fmi2Status set_debug_logging(fmi2Component component, fmi2Boolean loggingOn, size_t nCategories,
                                    const fmi2String categories[])
{
    (void)nCategories;
    (void)categories;
    COMPONENT
    c->logging_on = loggingOn;
    return fmi2OK;
}

static fmi2Status setup_experiment(fmi2Component component, fmi2Boolean toleranceDefined, fmi2Real tolerance,
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
    static fmi2Status function(fmi2Component component)                 \
    {                                                                   \
        COMPONENT                                                       \
        WITH_GIL(status_ = call(c, method, PyTuple_New(0), NULL))       \
    }

SIMPLE_CALL(enter_initialization_mode, "enter_initialization_mode")
SIMPLE_CALL(terminate, "terminate")

static fmi2Status exit_initialization_mode(fmi2Component component)
{
    COMPONENT
    WITH_GIL({
        status_ = call(c, "exit_initialization_mode", PyTuple_New(0), NULL);
        if (status_ < fmi2Error) c->kernel.armed = 1;
    })
}

static fmi2Status reset(fmi2Component component)
{
    COMPONENT
    WITH_GIL({
        PyObject *fresh = new_instance(c);
        if (fresh == NULL) {
            status_ = python_error(c, "fmi2Reset");
        } else {
            drop_batch(&c->batch);
            release_instance(c->instance);
            c->instance = fresh;
            c->kernel.armed = c->kernel.never = 0;
            status_ = drain_log(c);
        }
    })
}

/* ---- getters */

static fmi2Status get_values(Component *c, const char *method, const fmi2ValueReference vr[], size_t nvr,
                             PyObject **result)
{
    fmi2Status status = call(c, method, Py_BuildValue("(N)", reference_list(vr, nvr)), result);
    if (*result == NULL) return status;
    if (!PyList_Check(*result) || (size_t)PyList_Size(*result) != nvr) {
        Py_DECREF(*result);
        *result = NULL;
        log_message(c, fmi2Error, "logStatusError", "slave returned a list of the wrong length");
        return fmi2Error;
    }
    return status;
}

static fmi2Status get_real(fmi2Component component, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    COMPONENT
    if (kernel_ready(c) && kernel_get(&c->kernel.image, vr, nvr, value)) return fmi2OK;
    WITH_GIL({
        PyObject *values = NULL;
        status_ = get_values(c, "get_real", vr, nvr, &values);
        for (size_t i = 0; values && i < nvr; i++) value[i] = PyFloat_AsDouble(PyList_GET_ITEM(values, i));
        Py_XDECREF(values);
        if (PyErr_Occurred()) status_ = python_error(c, "fmi2GetReal");
    })
}

static fmi2Status get_integer(fmi2Component component, const fmi2ValueReference vr[], size_t nvr,
                              fmi2Integer value[])
{
    COMPONENT
    if (kernel_ready(c) && kernel_get_integers(&c->kernel.image, vr, nvr, value)) return fmi2OK;
    WITH_GIL({
        PyObject *values = NULL;
        status_ = get_values(c, "get_integer", vr, nvr, &values);
        for (size_t i = 0; values && i < nvr; i++) value[i] = (fmi2Integer)PyLong_AsLong(PyList_GET_ITEM(values, i));
        Py_XDECREF(values);
        if (PyErr_Occurred()) status_ = python_error(c, "fmi2GetInteger");
    })
}

static fmi2Status get_boolean(fmi2Component component, const fmi2ValueReference vr[], size_t nvr,
                              fmi2Boolean value[])
{
    COMPONENT
    WITH_GIL({
        PyObject *values = NULL;
        status_ = get_values(c, "get_boolean", vr, nvr, &values);
        for (size_t i = 0; values && i < nvr; i++) value[i] = PyObject_IsTrue(PyList_GET_ITEM(values, i)) == 1;
        Py_XDECREF(values);
    })
}

static fmi2Status get_string(fmi2Component component, const fmi2ValueReference vr[], size_t nvr,
                             fmi2String value[])
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

static PyObject *string_object(fmi2String text) { return PyUnicode_FromString(text ? text : ""); }

#define SETTER(function, method, type, to_python)                                                      \
    static fmi2Status function(fmi2Component component, const fmi2ValueReference vr[], size_t nvr,     \
                               const type value[])                                                     \
    {                                                                                                  \
        COMPONENT                                                                                      \
        WITH_GIL({                                                                                     \
            PyObject *values = PyList_New((Py_ssize_t)nvr);                                            \
            for (size_t i = 0; values && i < nvr; i++) PyList_SET_ITEM(values, (Py_ssize_t)i, to_python(value[i])); \
            status_ = set_values(c, method, vr, nvr, values);                                          \
        })                                                                                             \
    }

SETTER(set_real_python, "set_real", fmi2Real, PyFloat_FromDouble)
SETTER(set_integer, "set_integer", fmi2Integer, PyLong_FromLong)
SETTER(set_boolean, "set_boolean", fmi2Boolean, PyBool_FromLong)
SETTER(set_string, "set_string", fmi2String, string_object)

static fmi2Status set_real(fmi2Component component, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[])
{
    Component *c = (Component *)component;
    if (c != NULL && kernel_ready(c) && kernel_set_inputs(&c->kernel.image, vr, nvr, value)) {
        c->refused = 0;
        c->kernel.dirty = 1;
        return fmi2OK;
    }
    return set_real_python(component, vr, nvr, value);
}

/* ---- FMU state: the slave's, holding the loader's fields (ObsfmuMachine) */

static fmi2Status get_fmu_state(fmi2Component component, const ObsfmuMachine *machine, fmi2FMUstate *state)
{
    COMPONENT
    if (machine == NULL || state == NULL) return fmi2Error;
    WITH_GIL({
        PyObject *snapshot = NULL;
        PyObject *loader = Py_BuildValue("{s:i,s:s}", "fmi", machine->fmi, "state", machine->state);
        status_ = call(c, "get_fmu_state", loader ? Py_BuildValue("(N)", loader) : NULL, &snapshot);
        if (snapshot) {
            Py_XDECREF((PyObject *)*state);
            *state = snapshot;
        }
    })
}

/* slave.loader_fields(state) -> (None or {"fmi": int, "state": str}, time, initialized) into *machine
 * (machine->fmi = 0 when the state holds no loader fields); with the GIL held. */
static fmi2Status read_machine(Component *c, PyObject *state, ObsfmuMachine *machine)
{
    PyObject *fields = NULL, *loader = NULL;
    memset(machine, 0, sizeof *machine);
    fmi2Status status = call(c, "loader_fields", Py_BuildValue("(O)", state), &fields);
    if (fields && PyArg_ParseTuple(fields, "Odp", &loader, &machine->time, &machine->initialized)
        && PyDict_Check(loader)) {
        PyObject *fmi = PyDict_GetItemString(loader, "fmi"); /* borrowed */
        PyObject *name = PyDict_GetItemString(loader, "state");
        const char *text = name && PyUnicode_Check(name) ? PyUnicode_AsUTF8(name) : NULL;
        if (fmi && PyLong_Check(fmi) && text && strlen(text) < sizeof machine->state) {
            machine->fmi = (int)PyLong_AsLong(fmi);
            strcpy(machine->state, text);
        }
    }
    Py_XDECREF(fields);
    if (PyErr_Occurred()) status = python_error(c, "loader_fields");
    return status;
}

static fmi2Status machine_of(fmi2Component component, fmi2FMUstate state, ObsfmuMachine *machine)
{
    COMPONENT
    if (state == NULL || machine == NULL) return fmi2Error;
    WITH_GIL(status_ = read_machine(c, (PyObject *)state, machine))
}

static fmi2Status set_fmu_state(fmi2Component component, fmi2FMUstate state)
{
    COMPONENT
    if (state == NULL) return fmi2Error;
    WITH_GIL(status_ = call(c, "set_fmu_state", Py_BuildValue("(O)", (PyObject *)state), NULL))
}

static fmi2Status free_fmu_state(fmi2Component component, fmi2FMUstate *state)
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

static fmi2Status serialized_fmu_state_size(fmi2Component component, fmi2FMUstate state, size_t *size)
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

static fmi2Status serialize_fmu_state(fmi2Component component, fmi2FMUstate state, fmi2Byte buffer[],
                                      size_t size)
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

static fmi2Status deserialize_fmu_state(fmi2Component component, const fmi2Byte serializedState[], size_t size,
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

/* ---- inputs and stepping */

static fmi2Status set_real_input_derivatives(fmi2Component component, const fmi2ValueReference vr[], size_t nvr,
                                             const fmi2Integer order[], const fmi2Real value[])
{
    COMPONENT
    if (kernel_ready(c) && kernel_set_derivatives(&c->kernel.image, vr, nvr, order, value)) {
        c->kernel.dirty = 1;
        return fmi2OK;
    }
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

static fmi2Status get_real_output_derivatives(fmi2Component component, const fmi2ValueReference vr[], size_t nvr,
                                              const fmi2Integer order[], fmi2Real value[])
{
    COMPONENT
    WITH_GIL({
        PyObject *orders = PyList_New((Py_ssize_t)nvr);
        for (size_t i = 0; orders && i < nvr; i++) PyList_SET_ITEM(orders, (Py_ssize_t)i, PyLong_FromLong(order[i]));
        PyObject *values = NULL;
        status_ = call(c, "get_real_output_derivatives", Py_BuildValue("(NN)", reference_list(vr, nvr), orders),
                       &values);
        if (values && (!PyList_Check(values) || (size_t)PyList_Size(values) != nvr)) {
            Py_CLEAR(values);
            log_message(c, fmi2Error, "logStatusError", "slave returned a list of the wrong length");
            status_ = fmi2Error;
        }
        for (size_t i = 0; values && i < nvr; i++) value[i] = PyFloat_AsDouble(PyList_GET_ITEM(values, i));
        Py_XDECREF(values);
        if (PyErr_Occurred()) status_ = python_error(c, "fmi2GetRealOutputDerivatives");
    })
}

static fmi2Status clear_input_derivatives(fmi2Component component, const fmi2ValueReference vr[], size_t nvr)
{
    COMPONENT
    WITH_GIL(status_ = call(c, "clear_input_derivatives", Py_BuildValue("(N)", reference_list(vr, nvr)), NULL))
}

static fmi2Status do_step(fmi2Component component, fmi2Real currentCommunicationPoint,
                          fmi2Real communicationStepSize, fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    (void)noSetFMUStatePriorToCurrentPoint;
    COMPONENT
    if (kernel_ready(c) && kernel_advance(c, currentCommunicationPoint, communicationStepSize)) return fmi2OK;
    WITH_GIL({
        PyObject *result = NULL;
        status_ = call(c, "do_step", Py_BuildValue("(dd)", currentCommunicationPoint, communicationStepSize),
                       &result);
        if (result) {
            if (PyObject_IsTrue(result) != 1 && status_ < fmi2Discard) status_ = fmi2Discard;
            Py_DECREF(result);
        }
    })
}

/* Bind the slave's vectors for these value references (slave.batch_plan), unless bound already. */
static fmi2Status bind_batch(Component *c, const fmi2ValueReference vr[], size_t nvr, int slopes,
                             const fmi2ValueReference out_vr[], size_t nout)
{
    Batch *b = &c->batch;
    if (b->step != NULL && b->ninputs == nvr && b->noutputs == nout && b->slopes == slopes &&
        (nvr == 0 || memcmp(b->inputs, vr, nvr * sizeof *vr) == 0) &&
        (nout == 0 || memcmp(b->outputs, out_vr, nout * sizeof *out_vr) == 0))
        return fmi2OK;
    drop_batch(b);
    PyObject *vectors = NULL;
    fmi2Status status = call(c, "batch_plan", Py_BuildValue("(NON)", reference_list(vr, nvr),
                                                            slopes ? Py_True : Py_False,
                                                            reference_list(out_vr, nout)), &vectors);
    if (vectors == NULL) return status;
    size_t sizes[3] = {nvr, nvr, nout};
    int bound = 0;
    if (PyTuple_Check(vectors) && PyTuple_Size(vectors) == 3) {
        for (; bound < 3; bound++) {
            Py_buffer *view = &b->buffers[bound];
            if (PyObject_GetBuffer(PyTuple_GET_ITEM(vectors, bound), view, PyBUF_WRITABLE | PyBUF_C_CONTIGUOUS) != 0)
                break;
            if (view->len != (Py_ssize_t)(sizes[bound] * sizeof(double)) || view->itemsize != sizeof(double)) {
                PyBuffer_Release(view);
                PyErr_SetString(PyExc_TypeError, "batch_plan returned a vector of the wrong size");
                break;
            }
        }
    }
    Py_DECREF(vectors);
    b->inputs = malloc(nvr * sizeof *vr + 1);
    b->outputs = malloc(nout * sizeof *out_vr + 1);
    if (bound == 3 && b->inputs && b->outputs) b->step = PyObject_GetAttrString(c->instance, "step_batched");
    if (b->step == NULL) {
        while (bound > 0) PyBuffer_Release(&b->buffers[--bound]);
        free(b->inputs);
        free(b->outputs);
        memset(b, 0, sizeof *b);
        if (!PyErr_Occurred()) PyErr_SetString(PyExc_TypeError, "batch_plan did not return three float vectors");
        return python_error(c, "obsfmuDoStepBatched");
    }
    if (nvr) memcpy(b->inputs, vr, nvr * sizeof *vr);
    if (nout) memcpy(b->outputs, out_vr, nout * sizeof *out_vr);
    b->slopes = slopes;
    b->ninputs = nvr;
    b->noutputs = nout;
    return status;
}

/* obsfmuDoStepBatched (obsfmu_native.h): set the inputs (and slopes), step, read the outputs in one
 * call of slave.step_batched. *stepped = 1 when the step was taken (the outputs are then written). */
static fmi2Status do_step_batched(fmi2Component component, fmi2Real t, fmi2Real h, const fmi2ValueReference vr[],
                                  size_t nvr, const fmi2Real value[], const fmi2Real slope[],
                                  const fmi2ValueReference out_vr[], size_t nout, fmi2Real out[], int *stepped)
{
    *stepped = 0;
    COMPONENT
    /* in C: the inputs, their slopes, the step and the outputs; anything the kernel cannot vouch for: all of it in
     * Python (which sets the same inputs and slopes again) */
    if (kernel_ready(c) && kernel_readable(&c->kernel.image, out_vr, nout) &&
        kernel_set_inputs(&c->kernel.image, vr, nvr, value)) {
        c->kernel.dirty = 1;
        if ((slope == NULL || kernel_set_derivatives(&c->kernel.image, vr, nvr, NULL, slope)) &&
            kernel_advance(c, t, h) && kernel_get(&c->kernel.image, out_vr, nout, out)) {
            *stepped = 1;
            return fmi2OK;
        }
    }
    WITH_GIL({
        status_ = bind_batch(c, vr, nvr, slope != NULL, out_vr, nout);
        if (status_ < fmi2Error) {
            Batch *b = &c->batch;
            if (nvr) memcpy(b->buffers[0].buf, value, nvr * sizeof(double));
            if (nvr && slope) memcpy(b->buffers[1].buf, slope, nvr * sizeof(double));
            PyObject *time = PyFloat_FromDouble(t);
            PyObject *size = PyFloat_FromDouble(h);
            PyObject *args[2];                        /* (no braces: this is a macro argument) */
            args[0] = time;
            args[1] = size;
            PyObject *result = time && size ? PyObject_Vectorcall(b->step, args, 2, NULL) : NULL;
            Py_XDECREF(time);
            Py_XDECREF(size);
            if (result == NULL) {
                status_ = python_error(c, "obsfmuDoStepBatched");
            } else {
                fmi2Status logged = drain_log(c);
                if (logged > status_) status_ = logged;
                if (PyObject_IsTrue(result) == 1) {
                    *stepped = 1;
                    if (nout) memcpy(out, b->buffers[2].buf, nout * sizeof(double));
                } else if (status_ < fmi2Discard) {
                    status_ = fmi2Discard;
                }
                Py_DECREF(result);
            }
        }
    })
}

static size_t variable_count(fmi2Component component)
{
    Component *c = (Component *)component;
    return c ? c->variables : 0;
}

static int refused(fmi2Component component)
{
    Component *c = (Component *)component;
    return c != NULL && c->refused;
}

OBSFMU_BRIDGE_EXPORT const ObsfmuBridge *obsfmu_bridge(void)
{
    static const ObsfmuBridge table = {
        OBSFMU_BRIDGE_ABI, start, instantiate, free_instance, set_debug_logging, setup_experiment,
        enter_initialization_mode, exit_initialization_mode, terminate, reset,
        get_real, get_integer, get_boolean, get_string, set_real, set_integer, set_boolean, set_string,
        get_fmu_state, machine_of, set_fmu_state, free_fmu_state, serialized_fmu_state_size, serialize_fmu_state,
        deserialize_fmu_state, set_real_input_derivatives, clear_input_derivatives, do_step, refused,
        do_step_batched, get_real_output_derivatives, variable_count, start_isolated,
    };
    return &table;
}
