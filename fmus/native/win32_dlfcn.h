/* The few POSIX calls of the loaders, over the Win32 API: the win64 build of the loaders (docs/portability.md,
 * "Windows").  Included by loader_common.h instead of <dlfcn.h> when _WIN32 is defined; pthread (winpthreads),
 * stat, strtok_r and the rest come with MinGW-w64.
 *
 *   dlopen(path, mode)        LoadLibraryExW on the UTF-8 path as UTF-16 with backslashes, with
 *                             LOAD_WITH_ALTERED_SEARCH_PATH: a DLL's own folder is searched for the DLLs it
 *                             needs (the bridge next to the loader, vcruntime140.dll next to python3X.dll);
 *                             RTLD_NOLOAD: GetModuleHandleExW, RTLD_NODELETE: pinned
 *   dlsym(handle, name)       GetProcAddress; RTLD_DEFAULT: every module of the process, in load order
 *   dlclose, dlerror          FreeLibrary, the last error's code
 *
 * Windows has no global symbol namespace: RTLD_GLOBAL changes nothing (the bridge and numpy's extension
 * modules link python3X.dll by name, and Windows hands them the one already loaded). */
#ifndef OBSFMU_WIN32_DLFCN_H
#define OBSFMU_WIN32_DLFCN_H

#define PSAPI_VERSION 2 /* EnumProcessModules from kernel32 (K32EnumProcessModules): no psapi.dll */
#include "obsfmu_native.h" /* windows.h, obsfmu_wide */
#include <psapi.h>

#define RTLD_LAZY 0x1
#define RTLD_NOW 0x2
#define RTLD_NOLOAD 0x4
#define RTLD_GLOBAL 0x100
#define RTLD_LOCAL 0
#define RTLD_NODELETE 0x1000
#define RTLD_DEFAULT ((void *)0)
#define OBSFMU_MODULES 1024

static char obsfmu_dl_message[160];

static void obsfmu_dl_failed(const char *what)
{
    DWORD code = GetLastError();
    snprintf(obsfmu_dl_message, sizeof obsfmu_dl_message, "%s failed (Windows error %lu%s)", what,
             (unsigned long)code, code == ERROR_MOD_NOT_FOUND ? ": it, or a DLL it needs, is not found"
                                  : code == ERROR_BAD_EXE_FORMAT ? ": not a 64-bit Windows DLL" : "");
}

static void *dlopen(const char *path, int mode)
{
    HMODULE module = NULL;
    wchar_t *wide = obsfmu_wide(path);
    if (wide == NULL) {
        snprintf(obsfmu_dl_message, sizeof obsfmu_dl_message, "the path is not UTF-8");
        return NULL;
    }
    if (mode & RTLD_NOLOAD) {
        DWORD flags = (mode & RTLD_NODELETE) ? GET_MODULE_HANDLE_EX_FLAG_PIN : 0;
        if (!GetModuleHandleExW(flags, wide, &module)) module = NULL;
    } else {
        module = LoadLibraryExW(wide, NULL, LOAD_WITH_ALTERED_SEARCH_PATH);
    }
    if (module == NULL) obsfmu_dl_failed(mode & RTLD_NOLOAD ? "GetModuleHandleExW" : "LoadLibraryExW");
    free(wide);
    return (void *)module;
}

/* The modules of the process, in load order (the program first); their number. */
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

#endif
