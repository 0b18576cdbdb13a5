/* A tiny Windows FMI 2.0 host (issue 28.7): loads an obsfmu loader DLL and instantiates it once.
 * usage: win_host.exe LOADER.dll RESOURCE_URI GUID -- prints the loader's log lines and "instance: NULL|created". */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <windows.h>

#include "fmi2Functions.h"

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    (void)env;
    va_list arguments;
    va_start(arguments, message);
    printf("log %s [%d] %s: ", name ? name : "", (int)status, category ? category : "");
    vprintf(message, arguments);
    printf("\n");
    va_end(arguments);
}

int main(int argc, char **argv)
{
    if (argc != 4) return 2;
    HMODULE loader = LoadLibraryA(argv[1]);
    if (loader == NULL) {
        printf("LoadLibrary failed: Windows error %lu\n", (unsigned long)GetLastError());
        return 3;
    }
    fmi2GetVersionTYPE *version = (fmi2GetVersionTYPE *)(void *)GetProcAddress(loader, "fmi2GetVersion");
    fmi2InstantiateTYPE *instantiate = (fmi2InstantiateTYPE *)(void *)GetProcAddress(loader, "fmi2Instantiate");
    if (version == NULL || instantiate == NULL) {
        printf("missing FMI 2.0 functions\n");
        return 4;
    }
    printf("fmi2GetVersion: %s\n", version());
    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    fmi2Component instance = instantiate("win", fmi2CoSimulation, argv[3], argv[2], &callbacks, fmi2False, fmi2True);
    printf("instance: %s\n", instance ? "created" : "NULL");
    fflush(stdout);
    return 0;
}
