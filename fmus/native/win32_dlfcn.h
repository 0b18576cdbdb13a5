/* The few POSIX calls of the loaders, over the Win32 API: a win64 build of the FMI 2.0 loader (docs/portability.md,
 * "Windows and macOS").  Included by loader_common.h instead of <dlfcn.h> and <link.h> when _WIN32 is defined;
 * pthread (winpthreads), stat, strtok_r and the rest come with MinGW-w64.
 *
 *   dlopen(path, mode)        LoadLibraryExA (RTLD_NOLOAD: GetModuleHandleExA; RTLD_NODELETE: pinned)
 *   dlsym(handle, name)       GetProcAddress; RTLD_DEFAULT: every module of the process, in load order
 *   dlclose, dlerror          FreeLibrary, the last error's code
 *   dl_iterate_phdr           EnumProcessModules + GetModuleFileNameA (the program first, unnamed)
 *
 * Windows has no global symbol namespace: RTLD_GLOBAL changes nothing (numpy's extension modules link
 * python3X.dll by name, which is what a Windows CPython provides). */
#ifndef OBSFMU_WIN32_DLFCN_H
#define OBSFMU_WIN32_DLFCN_H

#define PSAPI_VERSION 2 /* EnumProcessModules from kernel32 (K32EnumProcessModules): no psapi.dll */
#define WIN32_LEAN_AND_MEAN
#define NOGDI           /* no wingdi.h: its ERROR macro is a state name of the loader */
#include <windows.h>
#include <psapi.h>
#include <stdio.h>
#undef ERROR

#define RTLD_LAZY 0x1
#define RTLD_NOW 0x2
#define RTLD_NOLOAD 0x4
#define RTLD_GLOBAL 0x100
#define RTLD_LOCAL 0
#define RTLD_NODELETE 0x1000
#define RTLD_DEFAULT ((void *)0)
#define OBSFMU_MODULES 1024

static char obsfmu_dl_message[128];

static void obsfmu_dl_failed(const char *what)
{
    snprintf(obsfmu_dl_message, sizeof obsfmu_dl_message, "%s failed (Windows error %lu)", what,
             (unsigned long)GetLastError());
}

static void *dlopen(const char *path, int mode)
{
    HMODULE module = NULL;
    if (mode & RTLD_NOLOAD) {
        DWORD flags = (mode & RTLD_NODELETE) ? GET_MODULE_HANDLE_EX_FLAG_PIN : 0;
        if (!GetModuleHandleExA(flags, path, &module)) module = NULL;
    } else {
        module = LoadLibraryExA(path, NULL, LOAD_WITH_ALTERED_SEARCH_PATH); /* its own folder for its DLLs */
    }
    if (module == NULL) obsfmu_dl_failed(mode & RTLD_NOLOAD ? "GetModuleHandleExA" : "LoadLibraryExA");
    return (void *)module;
}

static DWORD obsfmu_modules(HMODULE *modules)
{
    DWORD bytes = 0;
    if (!EnumProcessModules(GetCurrentProcess(), modules, OBSFMU_MODULES * sizeof(HMODULE), &bytes)) return 0;
    bytes /= sizeof(HMODULE);
    return bytes < OBSFMU_MODULES ? bytes : OBSFMU_MODULES;
}

static void *dlsym(void *handle, const char *name)
{
    if (handle != RTLD_DEFAULT) return (void *)GetProcAddress((HMODULE)handle, name);
    HMODULE modules[OBSFMU_MODULES];
    DWORD count = obsfmu_modules(modules);
    for (DWORD i = 0; i < count; i++) {
        FARPROC found = GetProcAddress(modules[i], name);
        if (found != NULL) return (void *)found;
    }
    return NULL;
}

static int dlclose(void *handle) { return FreeLibrary((HMODULE)handle) ? 0 : -1; }

static char *dlerror(void) { return obsfmu_dl_message; }

struct dl_phdr_info {
    const char *dlpi_name; /* the only member the loaders read */
};

static int dl_iterate_phdr(int (*callback)(struct dl_phdr_info *, size_t, void *), void *data)
{
    HMODULE modules[OBSFMU_MODULES];
    DWORD count = obsfmu_modules(modules);
    char name[MAX_PATH];
    for (DWORD i = 0; i < count; i++) {
        if (i == 0) name[0] = '\0'; /* the program itself, unnamed as on Linux */
        else if (!GetModuleFileNameA(modules[i], name, sizeof name)) continue;
        struct dl_phdr_info info = {name};
        int stop = callback(&info, sizeof info, data);
        if (stop) return stop;
    }
    return 0;
}

#endif
