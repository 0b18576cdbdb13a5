/*
 * What the FMI 2.0 loader (loader.c) and the FMI 3.0 loader (loader_fmi3.c) share: everything that
 * does not depend on the FMI version (details: docs/portability.md, docs/fmi3.md).
 *
 *   - finding or starting Python and loading the BRIDGE, once per process (get_bridge); a standalone FMU
 *     (obsfmu build --standalone) starts the runtime it carries, isolated (load_runtime);
 *   - the CORE of an instance: the bridge's component, the state machine's state and time, where
 *     messages go (an fmi2CallbackFunctions: the FMI 3 loader points it at a trampoline), and the
 *     rule that a FAILED call moves the instance to the version's failure state while a call the
 *     slave REFUSED (it changed nothing) leaves it where it was (after());
 *   - FMU states: the slave's, which hold the loader's fields (FMI version, state machine state; the
 *     time is the slave's): one serialized format, the slave's (fmus/runtime/state_format.py), with one
 *     identity check and one checksum; the loader validates its fields whenever a state comes back.
 *
 * Each loader includes this file once; everything here is static (nothing is exported).
 * The bridge is the same for both FMI versions: it speaks the FMI 2.0 signatures with the slave's
 * scalar value references (obsfmu_native.h).
 */
#ifndef OBSFMU_LOADER_COMMON_H
#define OBSFMU_LOADER_COMMON_H

#if defined(_WIN32)
#include "win32_dlfcn.h" /* dlopen & co. over LoadLibraryExW & co. (the win64 build: docs/portability.md) */
#define OBSFMU_EXPORT __declspec(dllexport)
#elif defined(__APPLE__)
#include <dlfcn.h>
#include <mach-o/dyld.h> /* _dyld_image_count, _dyld_get_image_name: the loaded images, in load order */
#define OBSFMU_EXPORT __attribute__((visibility("default")))
#else
#include <dlfcn.h>
#include <link.h>
#define OBSFMU_EXPORT __attribute__((visibility("default")))
#endif
#include <pthread.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdint.h>
#include <sys/stat.h>

#include "obsfmu_native.h"

#define OVERRIDE "OBSFMU_PYTHON"
#define PATH_SIZE 4096

static double magnitude(double x) { return x < 0 ? -x : x; }
static int finite(double x) { return x == x && magnitude(x) <= 1.7976931348623157e308; }

/* One line of `file` (its '\n' kept) into *line, grown as needed (getline(3), which MinGW lacks); its length, or -1
 * at the end of the file (or out of memory). */
static inline long read_line(char **line, size_t *capacity, FILE *file)
{
    size_t length = 0;
    int c;
    while ((c = fgetc(file)) != EOF) {
        if (length + 2 > *capacity) {
            size_t grown_size = *capacity ? 2 * *capacity : 256;
            char *grown = realloc(*line, grown_size);
            if (grown == NULL) return -1;
            *line = grown;
            *capacity = grown_size;
        }
        (*line)[length++] = (char)c;
        if (c == '\n') break;
    }
    if (length == 0) return -1;
    (*line)[length] = '\0';
    return (long)length;
}

/* ------------------------------------------------------------------ handles: checked, not trusted */

/* The instances and FMU states this loader issued and has not freed yet.  Every call looks its instance
 * (and FMU state) up here before using it: a pointer the FMU did not issue, or one already freed, is
 * refused without being dereferenced (docs/portability.md, "Handles").  An open-addressing hash set of
 * pointers: lookups take no lock (atomic loads: one hash, usually one probe); adding and removing take
 * the set's mutex.  A table that fills up with removed slots is replaced by a fresh one; the old table
 * is kept until the loader is unloaded, as a concurrent lookup may still be reading it. */
#define VACANT ((void *)0)
#define REMOVED ((void *)1)

typedef struct HandleTable {
    size_t mask;                  /* capacity - 1 (a power of two) */
    struct HandleTable *retired;  /* the table this one replaced */
    struct {
        _Atomic(void *) key;
        void *owner;              /* FMU states: the instance that issued it */
    } slot[];
} HandleTable;

typedef struct {
    _Atomic(HandleTable *) table;
    pthread_mutex_t lock;
    size_t filled, live;          /* slots not vacant (live or removed); live keys */
} Handles;

static Handles instances = {NULL, PTHREAD_MUTEX_INITIALIZER, 0, 0};
static Handles states = {NULL, PTHREAD_MUTEX_INITIALIZER, 0, 0};

static size_t handle_hash(const void *key) { return (size_t)(((uintptr_t)key * 0x9E3779B97F4A7C15ull) >> 29); }

/* The slot of `key` in `t`, or the first vacant slot of its probe sequence (NULL: the table is full). */
static size_t handle_probe(HandleTable *t, const void *key, int *found)
{
    size_t i = handle_hash(key) & t->mask;
    for (size_t n = 0; n <= t->mask; n++, i = (i + 1) & t->mask) {
        void *k = atomic_load_explicit(&t->slot[i].key, memory_order_acquire);
        if (k == key || k == VACANT) {
            *found = k == key;
            return i;
        }
    }
    *found = 0;
    return SIZE_MAX;
}

/* 1 if `key` was issued and not freed (no lock: this is on every call's path). */
static inline int handle_known(Handles *h, const void *key)
{
    HandleTable *t = atomic_load_explicit(&h->table, memory_order_acquire);
    int found = 0;
    if (t != NULL && (uintptr_t)key > 1) handle_probe(t, key, &found);
    return found;
}

/* Add `key` (issued by `owner`); 0 on success, -1 out of memory. */
static int handle_add(Handles *h, void *key, void *owner)
{
    pthread_mutex_lock(&h->lock);
    HandleTable *t = atomic_load_explicit(&h->table, memory_order_relaxed);
    if (t == NULL || 2 * (h->filled + 1) > t->mask + 1) { /* a fresh table, at most a quarter full */
        size_t capacity = 16;
        while (capacity < 4 * (h->live + 1)) capacity *= 2;
        HandleTable *fresh = calloc(1, sizeof(HandleTable) + capacity * sizeof fresh->slot[0]);
        if (fresh == NULL) {
            pthread_mutex_unlock(&h->lock);
            return -1;
        }
        fresh->mask = capacity - 1;
        fresh->retired = t;
        for (size_t i = 0; t && i <= t->mask; i++) {
            void *k = atomic_load_explicit(&t->slot[i].key, memory_order_relaxed);
            int found;
            if (k == VACANT || k == REMOVED) continue;
            size_t j = handle_probe(fresh, k, &found);
            fresh->slot[j].owner = t->slot[i].owner;
            atomic_store_explicit(&fresh->slot[j].key, k, memory_order_relaxed);
        }
        atomic_store_explicit(&h->table, fresh, memory_order_release);
        h->filled = h->live;
        t = fresh;
    }
    size_t i = handle_hash(key) & t->mask;   /* the first removed or vacant slot */
    while (1) {
        void *k = atomic_load_explicit(&t->slot[i].key, memory_order_relaxed);
        if (k == VACANT || k == REMOVED) {
            h->filled += k == VACANT;
            break;
        }
        i = (i + 1) & t->mask;
    }
    t->slot[i].owner = owner;
    atomic_store_explicit(&t->slot[i].key, key, memory_order_release);
    h->live++;
    pthread_mutex_unlock(&h->lock);
    return 0;
}

/* Remove `key`; 1 if it was there. */
static int handle_remove(Handles *h, const void *key)
{
    pthread_mutex_lock(&h->lock);
    HandleTable *t = atomic_load_explicit(&h->table, memory_order_relaxed);
    int found = 0;
    size_t i = t && (uintptr_t)key > 1 ? handle_probe(t, key, &found) : 0;
    if (found) {
        atomic_store_explicit(&t->slot[i].key, REMOVED, memory_order_release);
        h->live--;
    }
    pthread_mutex_unlock(&h->lock);
    return found;
}

/* Remove one key issued by `owner` and return it (NULL: none left). */
static void *handle_take_owned(Handles *h, const void *owner)
{
    void *taken = NULL;
    pthread_mutex_lock(&h->lock);
    HandleTable *t = atomic_load_explicit(&h->table, memory_order_relaxed);
    for (size_t i = 0; t && i <= t->mask && taken == NULL; i++) {
        void *k = atomic_load_explicit(&t->slot[i].key, memory_order_relaxed);
        if (k == VACANT || k == REMOVED || t->slot[i].owner != owner) continue;
        atomic_store_explicit(&t->slot[i].key, REMOVED, memory_order_release);
        h->live--;
        taken = k;
    }
    pthread_mutex_unlock(&h->lock);
    return taken;
}

static void handles_release(Handles *h)
{
    for (HandleTable *t = atomic_load(&h->table), *next; t != NULL; t = next) {
        next = t->retired;
        free(t);
    }
}

/* ------------------------------------------------------------------ finding Python */

static pthread_mutex_t lock = PTHREAD_MUTEX_INITIALIZER;
static void *bridge_library;          /* this loader's bridge (closed when the loader is unloaded) */
static const ObsfmuBridge *bridge;
static char start_failure[PATH_SIZE]; /* an interpreter that failed to start cannot be retried */

static int exists(const char *path) { return path[0] != '\0' && obsfmu_stat(path, NULL); }

/* "3.11.7 (main, ...)" has the version "3.11" (and "3.1" does not). */
static int same_version(const char *running, const char *wanted)
{
    size_t n = strlen(wanted);
    return running && strncmp(running, wanted, n) == 0 && (running[n] == '.' || running[n] == ' ' || running[n] == '\0');
}

/* The version number of Py_GetVersion()'s "3.12.1 (main, May  9 2024, ...)" into out (64 bytes): "3.12.1". */
static const char *version_number(const char *running, char *out)
{
    snprintf(out, 64, "%.*s", (int)(running ? strcspn(running, " ") : 0), running ? running : "");
    if (out[0] == '\0') snprintf(out, 64, "of unknown version");
    return out;
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
    FILE *file = obsfmu_fopen(path, "r");
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
    int directory = 0;
    program[0] = library[0] = '\0';
    snprintf(root, sizeof root, "%s", value);
    if (obsfmu_stat(value, &directory) && !directory) { /* <root>/bin/python */
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

/* dlopen the libpython `library` (RTLD_GLOBAL: extension modules resolve their symbols there) if it is Python
 * `version`; *must_start = 1 if it must be started.  NULL after a message ending in `hint`. */
static void *open_python(const char *library, const char *version, int *must_start, const char *hint, char *message,
                         size_t size)
{
    void *python = dlopen(library, RTLD_NOW | RTLD_GLOBAL);
    if (python == NULL) {
        snprintf(message, size, "cannot load %s: %s; %s", library, dlerror(), hint);
        return NULL;
    }
    const char *(*get_version)(void) = (const char *(*)(void))dlsym(python, "Py_GetVersion");
    int (*initialized)(void) = (int (*)(void))dlsym(python, "Py_IsInitialized");
    if (get_version == NULL || initialized == NULL || !same_version(get_version(), version)) {
        char number[64];
        snprintf(message, size, "%s is not Python %s (it is %s); %s", library, version,
                 get_version ? version_number(get_version(), number) : "not a libpython", hint);
        return NULL; /* never dlclose a libpython: it may have run already */
    }
    *must_start = !initialized();
    return python;
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
    return open_python(library, version, must_start, hint, message, size);
}

/* ------------------------------------------------------------------ a standalone FMU's own Python */

/* A standalone FMU (obsfmu build --standalone, fmus/standalone.py) carries its Python in
 * resources/<runtime>: the record's runtime* keys say where. */
static int standalone(const char *record)
{
    char runtime[PATH_SIZE];
    return obsfmu_record_value(record, "runtime", runtime, sizeof runtime)[0] != '\0';
}

/* The folder of a standalone FMU's runtime: <resources>/<runtime> (PATH_SIZE bytes). */
static void runtime_home(const char *resources, const char *record, char *home)
{
    char relative[PATH_SIZE];
    obsfmu_record_value(record, "runtime", relative, sizeof relative);
    snprintf(home, PATH_SIZE, "%s/%s", resources, relative);
}

/* Load the runtime of a standalone FMU: the libraries it bundles (runtime_preload, dependencies first,
 * RTLD_LOCAL: its extension modules find them by soname; one the process already has is kept), then its
 * libpython (RTLD_GLOBAL).  `home` receives the runtime's folder. */
static void *load_runtime(const char *resources, const char *record, char *home, int *must_start, char *message,
                          size_t size)
{
    char version[32], relative[PATH_SIZE], preload[PATH_SIZE], path[2 * PATH_SIZE + 2], *next = NULL;
    obsfmu_record_value(record, "python_version", version, sizeof version);
    runtime_home(resources, record, home);
    obsfmu_record_value(record, "runtime_preload", preload, sizeof preload);
    for (char *name = strtok_r(preload, " ", &next); name; name = strtok_r(NULL, " ", &next)) {
        const char *soname = strrchr(name, '/') ? strrchr(name, '/') + 1 : name;
        if (dlopen(soname, RTLD_NOW | RTLD_NOLOAD) != NULL) continue;
        snprintf(path, sizeof path, "%s/%s", home, name);
        if (dlopen(path, RTLD_NOW | RTLD_LOCAL) == NULL) {
            snprintf(message, size, "cannot load %s of this standalone FMU's Python: %s", path, dlerror());
            return NULL;
        }
    }
    obsfmu_record_value(record, "runtime_library", relative, sizeof relative);
    snprintf(path, sizeof path, "%s/%s", home, relative);
    return open_python(path, version, must_start, "the FMU's own Python is damaged: unzip the FMU again", message,
                       size);
}

/* ------------------------------------------------------------------ one Python start per process */

/* Every obsfmu loader (FMI 2.0 and 3.0, of any FMU) exports this mutex; the one of the loader loaded
 * FIRST in the process guards finding and starting Python for all of them, so two FMUs instantiated at
 * once from two threads never both start an interpreter (docs/portability.md, "One Python start per
 * process").  Found in the list of loaded objects in load order (Linux: dl_iterate_phdr; macOS: dyld's images;
 * Windows: EnumProcessModules), pinned (RTLD_NODELETE, GET_MODULE_HANDLE_EX_FLAG_PIN) so that it stays while any
 * loader may still use it. */
#define GUARD "obsfmu_python_start_guard_1"
OBSFMU_EXPORT pthread_mutex_t obsfmu_python_start_guard_1 = PTHREAD_MUTEX_INITIALIZER;

#ifdef _WIN32
/* The guard of the first loaded obsfmu loader: the modules in load order, each asked for the symbol; the one
 * found is pinned (GET_MODULE_HANDLE_EX_FLAG_PIN: never unloaded). */
static pthread_mutex_t *process_guard(void)
{
    HMODULE modules[OBSFMU_MODULES], pinned;
    DWORD count = obsfmu_modules(modules);
    for (DWORD i = 0; i < count; i++) {
        pthread_mutex_t *guard = (pthread_mutex_t *)(void *)GetProcAddress(modules[i], GUARD);
        if (guard != NULL && GetModuleHandleExW(GET_MODULE_HANDLE_EX_FLAG_FROM_ADDRESS | GET_MODULE_HANDLE_EX_FLAG_PIN,
                                                (LPCWSTR)(void *)guard, &pinned))
            return guard;
    }
    return &obsfmu_python_start_guard_1;
}
#else
typedef struct {
    char **names;
    size_t count, capacity;
} Loaded;

static int note_name(Loaded *loaded, const char *object)
{
    if (object == NULL || object[0] == '\0') return 0; /* the program itself */
    if (loaded->count == loaded->capacity) {
        size_t capacity = loaded->capacity ? 2 * loaded->capacity : 64;
        char **grown = realloc(loaded->names, capacity * sizeof(char *));
        if (grown == NULL) return 1;
        loaded->names = grown;
        loaded->capacity = capacity;
    }
    size_t length = strlen(object) + 1;
    char *name = malloc(length);
    if (name == NULL) return 1;
    memcpy(name, object, length);
    loaded->names[loaded->count++] = name;
    return 0;
}

#ifdef __APPLE__
/* The loaded images in load order (dyld's list; image 0 is the program). */
static void list_loaded(Loaded *loaded)
{
    for (uint32_t i = 1, n = _dyld_image_count(); i < n; i++)
        if (note_name(loaded, _dyld_get_image_name(i))) break;
}
#else
static int note_loaded(struct dl_phdr_info *info, size_t size, void *data)
{
    (void)size;
    return note_name(data, info->dlpi_name);
}

/* The loaded objects in load order (the dynamic loader's list). */
static void list_loaded(Loaded *loaded) { dl_iterate_phdr(note_loaded, loaded); }
#endif

/* The guard of the first loaded obsfmu loader (this one's if none is found: no worse than one per loader). */
static pthread_mutex_t *process_guard(void)
{
    Loaded loaded = {NULL, 0, 0};
    pthread_mutex_t *guard = NULL;
    list_loaded(&loaded);   /* names first: no dlopen while the list is locked */
    for (size_t i = 0; i < loaded.count && guard == NULL; i++) {
        void *object = dlopen(loaded.names[i], RTLD_LAZY | RTLD_NOLOAD);
        guard = object ? (pthread_mutex_t *)dlsym(object, GUARD) : NULL;
        if (guard != NULL) dlopen(loaded.names[i], RTLD_LAZY | RTLD_NOLOAD | RTLD_NODELETE); /* pinned */
        if (object != NULL) dlclose(object);
    }
    for (size_t i = 0; i < loaded.count; i++) free(loaded.names[i]);
    free(loaded.names);
    return guard ? guard : &obsfmu_python_start_guard_1;
}
#endif

/* The bridge of this FMU, with a Python to run it; NULL and a message saying what is missing. */
static const ObsfmuBridge *get_bridge(const char *resources, const char *record, char *message, size_t size)
{
    pthread_mutex_lock(&lock);
    if (bridge == NULL && start_failure[0]) snprintf(message, size, "%s", start_failure);
    if (bridge != NULL || start_failure[0]) {
        pthread_mutex_unlock(&lock);
        return bridge;
    }
    pthread_mutex_t *guard = process_guard();
    pthread_mutex_lock(guard);   /* held from "does Python run?" to "it runs" */

    char version[32], program[PATH_SIZE] = "", name[PATH_SIZE], path[2 * PATH_SIZE], search[PATH_SIZE];
    obsfmu_record_value(record, "python_version", version, sizeof version);
    obsfmu_record_value(record, "bridge", name, sizeof name);
    obsfmu_record_value(record, "runtime_path", search, sizeof search);
    int must_start = 0, own = standalone(record);
    int (*initialized)(void) = (int (*)(void))dlsym(RTLD_DEFAULT, "Py_IsInitialized");
    if (initialized != NULL) { /* the process has Python: use it */
        const char *(*get_version)(void) = (const char *(*)(void))dlsym(RTLD_DEFAULT, "Py_GetVersion");
        const char *running = get_version ? get_version() : "";
        char number[64];
        if (!same_version(running, version)) {
            snprintf(message, size, "this process runs Python %s, but this FMU's binary was built for Python %s: "
                     "load it from a Python %s process, or rebuild it (obsfmu build) with the host's Python%s",
                     version_number(running, number), version, version, own ? " (a standalone FMU runs its own Python only in a process "
                     "that runs no Python)" : "");
            goto done;
        }
        must_start = !initialized();
        obsfmu_record_value(record, "python_executable", program, sizeof program);
        if (!must_start) own = 0;        /* a process holds one interpreter: the host's */
        else if (own) runtime_home(resources, record, program); /* a libpython not started yet: our runtime's */
    } else if (own ? load_runtime(resources, record, program, &must_start, message, size) == NULL
                   : load_python(record, program, &must_start, message, size) == NULL) {
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
    if (must_start && (own ? table()->startIsolated(program, search, message, size)
                           : table()->start(program, message, size)) != 0) {
        snprintf(start_failure, sizeof start_failure, "%s", message);
        goto done; /* the bridge stays loaded: the half-started interpreter may point into it */
    }
    bridge_library = library;
    bridge = table();
done:
    pthread_mutex_unlock(guard);
    pthread_mutex_unlock(&lock);
    return bridge;
}

__attribute__((destructor)) static void unload(void)
{
    if (bridge_library) dlclose(bridge_library);
    handles_release(&instances);
    handles_release(&states);
}

/* ------------------------------------------------------------------ the core of an instance */

/* What differs between the FMI versions in the parts below. */
typedef struct {
    int fmi;                     /* 2 or 3: kept in every FMU state */
    unsigned every_state;        /* mask of the state machine's states */
    unsigned before_init;        /* states before exitInitializationMode (the slave not initialized) */
    unsigned after_init;         /* states after it (the slave initialized); the others: either */
    unsigned failed;             /* the state a failed call (fmi2Error/fmi3Error) leads to */
    const char *(*state_name)(unsigned state);
    const char *prefix;          /* "fmi2" or "fmi3", for messages */
} Version;

/* A start value of an exported copy (resources/obsfmu_start.txt, see core_read_starts). */
typedef struct {
    char type;                    /* 'R' real, 'I' integer */
    fmi2ValueReference vr;        /* the slave's value reference */
    double value;
} Start;

typedef struct {
    const Version *version;
    const ObsfmuBridge *bridge;
    fmi2Component inner;          /* the bridge's component */
    unsigned state;               /* one bit of version->every_state */
    double time;                  /* the FMU's current communication point */
    fmi2CallbackFunctions callbacks;
    char *name;
    Start *starts;                /* applied after instantiation and after every reset */
    size_t start_count;
    size_t variable_count;        /* the slave's scalar variables: a bound for nvr */
} Core;

static void say(const fmi2CallbackFunctions *callbacks, const char *name, fmi2Status status, const char *format, ...)
{
    char message[8192];
    va_list arguments;
    va_start(arguments, format);
    vsnprintf(message, sizeof message, format, arguments);
    va_end(arguments);
    obsfmu_emit(callbacks, name, status, obsfmu_category(status), message);
}

#define refuse(core, ...) (say(&(core)->callbacks, (core)->name, fmi2Error, __VA_ARGS__), fmi2Error)

/* fmi2OK when a step of size h may start at t (the instance's time); else fmi2Error, logged as a refusal of `call`. */
static fmi2Status check_step(Core *c, const char *call, double t, double h)
{
    if (!finite(h) || h <= 0)
        return refuse(c, "%s: communicationStepSize %g is not a positive finite number", call, h);
    if (!finite(t) || magnitude(t - c->time) > 1e-9 * (magnitude(c->time) > 1 ? magnitude(c->time) : 1))
        return refuse(c, "%s: currentCommunicationPoint %.17g is not the FMU's current time %.17g", call, t, c->time);
    return fmi2OK;
}

/* The status of a call that reached the bridge.  fmi2Error: a call the slave refused (it changed
 * nothing) leaves the instance in its state, a failed one moves it to the version's failure state. */
static fmi2Status after(Core *c, fmi2Status status)
{
    if (status < fmi2Error) return status;
    if (!c->bridge->refused(c->inner)) c->state = c->version->failed;
    return fmi2Error;
}

/* ------------------------------------------------------------------ FMU states */

/* An FMU state is the slave's (an object of the bridge): it holds the loader's fields, which the
 * loader hands over when the state is saved and validates whenever a state comes back (set or
 * deserialized: a state of this FMI version, a known state machine state that agrees with the
 * slave's initialization).  The serialized form is the slave's alone (fmus/runtime/state_format.py: format
 * version, identity = model name and GUID / instantiationToken, SHA-256 of everything). */

static unsigned state_bit(const Version *version, const char *name)
{
    for (unsigned bit = 1; bit != 0 && bit <= version->every_state; bit <<= 1)
        if ((version->every_state & bit) && strcmp(version->state_name(bit), name) == 0) return bit;
    return 0;
}

/* The loader's fields of `state`, validated: fmi2OK and the state machine state in *bit and the time in
 * *time, or fmi2Error after a message (nothing changes). */
static fmi2Status core_machine(Core *c, const char *call, void *state, unsigned *bit, double *time)
{
    ObsfmuMachine machine;
    fmi2Status status = c->bridge->machineOf(c->inner, state, &machine);
    if (status >= fmi2Error) return after(c, status);
    const Version *v = c->version;
    *bit = machine.fmi == v->fmi ? state_bit(v, machine.state) : 0;
    *time = machine.time;
    if (machine.fmi == 0)
        return refuse(c, "%s: the state holds no state machine fields (not saved by an obsfmu FMU binary)", call);
    if (machine.fmi != v->fmi)
        return refuse(c, "%s: this state was saved by the FMI %d.0 binary of this FMU; this is the FMI %d.0 binary",
                      call, machine.fmi, v->fmi);
    if (*bit == 0) return refuse(c, "%s: the state machine state %.31s of the state is unknown", call, machine.state);
    if ((machine.initialized && (*bit & v->before_init)) || (!machine.initialized && (*bit & v->after_init)))
        return refuse(c, "%s: the state is damaged: state machine state %s, but the slave %s initialized", call,
                      machine.state, machine.initialized ? "was" : "was not");
    return status;
}

/* fmi2Error after a message unless `state` is an FMU state this FMU issued and has not freed. */
#define KNOWN_STATE(c, call, state)                                                                         \
    if ((state) == NULL) return refuse(c, "%s: FMUState is NULL", call);                                   \
    if (!handle_known(&states, (state)))                                                                    \
        return refuse(c, "%s: FMUState %p is not a state of this FMU (another FMU's, a foreign pointer, or "   \
                      "freed already): nothing done", call, (void *)(state));

/* A state the bridge just made: registered, or freed again when it cannot be. */
static fmi2Status issued(Core *c, const char *call, void **state)
{
    if (handle_add(&states, *state, c) == 0) return fmi2OK;
    c->bridge->freeFMUstate(c->inner, state);
    return refuse(c, "%s: out of memory", call);
}

static fmi2Status core_get_state(Core *c, const char *call, void **state)
{
    if (state == NULL) return refuse(c, "%s: FMUState is NULL", call);
    void *old = *state;
    if (old != NULL && !handle_known(&states, old))
        return refuse(c, "%s: *FMUState is %p, neither NULL (a new state) nor a state of this FMU to update: set it "
                      "to NULL first", call, old);
    ObsfmuMachine machine = {c->version->fmi, "", 0.0, 0};
    snprintf(machine.state, sizeof machine.state, "%s", c->version->state_name(c->state));
    fmi2Status status = c->bridge->getFMUstate(c->inner, &machine, state);
    if (*state != old) {          /* a new state (an updated one replaces the old object) */
        if (old != NULL) handle_remove(&states, old);
        if (*state != NULL && issued(c, call, state) != fmi2OK) return fmi2Error;
    }
    return after(c, status);
}

static fmi2Status core_set_state(Core *c, const char *call, void *state)
{
    unsigned bit;
    double time;
    KNOWN_STATE(c, call, state)
    fmi2Status status = core_machine(c, call, state, &bit, &time);
    if (status >= fmi2Error) return status;
    status = c->bridge->setFMUstate(c->inner, state);
    if (status < fmi2Error) {
        c->state = bit;
        c->time = time;
    }
    return after(c, status);
}

static fmi2Status core_free_state(Core *c, const char *call, void **state)
{
    if (state == NULL) return fmi2OK;
    if (handle_known(&states, state))  /* fmusim 0.0.39 does this: free(c, s) instead of free(c, &s) */
        return refuse(c, "%s: given the FMU state itself instead of its address (call %s(instance, &state)): "
                      "nothing freed", call, call);
    if (*state == NULL) return fmi2OK;
    if (!handle_remove(&states, *state))
        return refuse(c, "%s: *FMUState %p is not a state of this FMU (another FMU's, a foreign pointer, or "
                      "freed already): nothing freed", call, *state);
    return after(c, c->bridge->freeFMUstate(c->inner, state));
}

/* The states an instance issued and the importer did not free: freed with the instance (FMI: freeing
 * an instance frees everything allocated for it). */
static void core_free_states(Core *c)
{
    void *state;
    while ((state = handle_take_owned(&states, c)) != NULL) c->bridge->freeFMUstate(c->inner, &state);
}

static fmi2Status core_serialized_size(Core *c, const char *call, void *state, size_t *size)
{
    KNOWN_STATE(c, call, state)
    if (size == NULL) return refuse(c, "%s: NULL argument", call);
    return after(c, c->bridge->serializedFMUstateSize(c->inner, state, size));
}

static fmi2Status core_serialize(Core *c, const char *call, void *state, fmi2Byte buffer[], size_t size)
{
    size_t needed = 0;
    KNOWN_STATE(c, call, state)
    if (buffer == NULL) return refuse(c, "%s: NULL argument", call);
    fmi2Status status = c->bridge->serializedFMUstateSize(c->inner, state, &needed);
    if (status >= fmi2Error) return after(c, status);
    if (size < needed) return refuse(c, "%s: buffer of %zu bytes, %zu needed", call, size, needed);
    return after(c, c->bridge->serializeFMUstate(c->inner, state, buffer, size));
}

/* The slave checks the bytes (format, identity, checksum, its own fields); then the loader its fields.
 * *state: a state of this FMU is overwritten (freed); anything else is not looked at (the standard
 * says the call constructs a new state, so an importer may pass an uninitialised variable). */
static fmi2Status core_deserialize(Core *c, const char *call, const fmi2Byte bytes[], size_t size, void **state)
{
    unsigned bit;
    double time;
    void *read = NULL;
    if (bytes == NULL || state == NULL) return refuse(c, "%s: NULL argument", call);
    if (size > OBSFMU_MAX_STATE_BYTES)
        return refuse(c, "%s: %zu bytes; an obsfmu FMU state has at most %zu (64 MiB): refused, nothing read", call,
                      size, OBSFMU_MAX_STATE_BYTES);
    fmi2Status status = c->bridge->deSerializeFMUstate(c->inner, bytes, size, &read);
    if (status >= fmi2Error || read == NULL) return after(c, status >= fmi2Error ? status : fmi2Error);
    fmi2Status checked = core_machine(c, call, read, &bit, &time);
    if (checked >= fmi2Error) {
        c->bridge->freeFMUstate(c->inner, &read);
        return checked;
    }
    if (issued(c, call, &read) != fmi2OK) return fmi2Error;
    if (*state != NULL && handle_remove(&states, *state)) c->bridge->freeFMUstate(c->inner, state);
    *state = read;
    return status > checked ? status : checked;
}

/* ------------------------------------------------------------------ instantiation */

/* The record of the FMU unzipped around `resources`, if its token (GUID, instantiationToken) is `token`;
 * NULL after one message (through `callbacks`) saying what is wrong. */
static char *checked_record(const fmi2CallbackFunctions *callbacks, const char *name, const char *call,
                            const char *resources, const char *location, const char *token, const char *token_name)
{
    char expected[128];
    char *record = resources ? obsfmu_read_record(resources) : NULL;
    if (record == NULL) {
        say(callbacks, name, fmi2Error, "%s: cannot read %s/" OBSFMU_RECORD " (resource location %s): not an unzipped "
            "obsfmu FMU", call, resources ? resources : "", location);
        return NULL;
    }
    obsfmu_record_value(record, "guid", expected, sizeof expected);
    if (token == NULL || strcmp(token, expected) != 0) {
        say(callbacks, name, fmi2Error, "%s: %s %s is not this FMU's (%s): the modelDescription.xml used does not "
            "belong to this binary", call, token_name, token ? token : "(null)", expected);
        free(record);
        return NULL;
    }
    return record;
}

/* ------------------------------------------------------------------ start values of an exported copy */

/* resources/obsfmu_start.txt, written by `obsfmu export` into the FMU copies it exports (fmus/export.py):
 * lines "<R|I> <the slave's value reference> <value>".  The loader sets them right after instantiation
 * and after every reset, so the copy's own defaults are the start values its modelDescription.xml
 * declares -- the exported system keeps its configuration in importers that ignore the SSP/OSP
 * parameter bindings.  No file: no start values.  0 on success, else a message. */
static int core_read_starts(Core *c, const char *resources, char *message, size_t size)
{
    char path[PATH_SIZE + 32], line[256];
    snprintf(path, sizeof path, "%s/" OBSFMU_STARTS, resources);
    FILE *file = obsfmu_fopen(path, "r");
    if (file == NULL) return 0;
    while (fgets(line, sizeof line, file)) {
        Start start;
        unsigned vr;
        if (line[0] == '#' || line[0] == '\n') continue;
        if (sscanf(line, " %c %u %lf", &start.type, &vr, &start.value) != 3 || (start.type != 'R' && start.type != 'I')) {
            snprintf(message, size, "%s is damaged (line: %.100s)", path, line);
            fclose(file);
            return -1;
        }
        start.vr = vr;
        Start *grown = realloc(c->starts, (c->start_count + 1) * sizeof(Start));
        if (grown == NULL) {
            fclose(file);
            snprintf(message, size, "out of memory");
            return -1;
        }
        c->starts = grown;
        c->starts[c->start_count++] = start;
    }
    fclose(file);
    return 0;
}

static fmi2Status core_apply_starts(Core *c)
{
    fmi2Status worst = fmi2OK;
    for (size_t i = 0; i < c->start_count && worst < fmi2Error; i++) {
        Start *start = &c->starts[i];
        fmi2Status status;
        if (start->type == 'R') {
            status = c->bridge->setReal(c->inner, &start->vr, 1, &start->value);
        } else {
            fmi2Integer integer = (fmi2Integer)start->value;
            status = c->bridge->setInteger(c->inner, &start->vr, 1, &integer);
        }
        worst = status > worst ? status : worst;
    }
    return worst;
}

/* ------------------------------------------------------------------ the life of a core */

/* Fill the core of a new instance whose bridge component is `inner` and set the copy's start
 * values; 0 on success (on failure the caller frees `inner` and the core, core_free). */
static int core_init(Core *c, const Version *version, const ObsfmuBridge *bridge, fmi2Component inner,
                     const char *name, unsigned state, const char *resources)
{
    char message[8192];
    c->version = version;
    c->bridge = bridge;
    c->inner = inner;
    c->state = state;
    c->time = 0.0;
    c->variable_count = bridge->variableCount(inner);
    c->name = malloc(strlen(name) + 1);
    if (c->name == NULL) return -1;
    strcpy(c->name, name);
    if (core_read_starts(c, resources, message, sizeof message) != 0) {
        say(&c->callbacks, name, fmi2Error, "%sInstantiate: %s", version->prefix, message);
        return -1;
    }
    return core_apply_starts(c) >= fmi2Error ? -1 : 0;
}

static void core_free(Core *c)
{
    free(c->name);
    free(c->starts);
    c->name = NULL;
    c->starts = NULL;
    c->start_count = 0;
}

/* fmi2Reset/fmi3Reset: a fresh slave, the copy's start values, state instantiated at time 0. */
static fmi2Status core_reset(Core *c, unsigned instantiated)
{
    fmi2Status status = c->bridge->reset(c->inner);
    if (status < fmi2Error) {
        fmi2Status set = core_apply_starts(c);
        status = set > status ? set : status;
    }
    if (status < fmi2Error) {
        c->state = instantiated;
        c->time = 0.0;
    }
    return after(c, status);
}

#endif
