/* pyconfig.h of the python.org CPython for Windows x64 (built with MSVC), as MinGW-w64 must see it to compile
 * the BRIDGE (bridge.c) of a win64 FMU against the building Python's own headers (fmus/native/windows.py puts
 * this file in place of that Python's Linux pyconfig.h in a copy of its include folder).  The bridge is compiled
 * for the same minor version as the Windows CPython the FMU carries, so the generic headers are the right ones;
 * only the platform's configuration differs.  It declares just what those headers read -- type sizes, the DLL
 * import rules, the Windows-only fields of PyConfig and PyPreConfig (MS_WINDOWS) -- to give the same structure
 * layouts and calling conventions as python3X.dll.  Written for obsfmu after CPython's PC/pyconfig.h. */
#ifndef Py_CONFIG_H
#define Py_CONFIG_H

#if !defined(_WIN64) || !defined(__x86_64__)
#error "this pyconfig.h describes the x86-64 Windows CPython only"
#endif

#include <io.h>
#include <float.h>
#include <stdio.h>
#include <basetsd.h>

#define MS_WIN32   /* Win32 and Win64 API */
#define MS_WIN64
#define MS_WINDOWS /* PyConfig.legacy_windows_stdio, PyPreConfig.legacy_windows_fs_encoding exist */
#define NT_THREADS
#define WITH_THREAD
#define PLATFORM "win32"
#define COMPILER "[gcc]"
#define PYD_PLATFORM_TAG "win_amd64"

/* the core is python3X.dll: its functions and data are imported (PyAPI_FUNC, PyAPI_DATA = __declspec(dllimport)) */
#define Py_ENABLE_SHARED 1
#define MS_COREDLL
#define HAVE_DECLSPEC_DLL

/* LLP64: long is 32 bits, pointers and size_t 64, wchar_t 16 (UTF-16) */
#define LONG_BIT 32
#define WORD_BIT 32
#define SIZEOF_SHORT 2
#define SIZEOF_INT 4
#define SIZEOF_LONG 4
#define SIZEOF_LONG_LONG 8
#define SIZEOF_FLOAT 4
#define SIZEOF_DOUBLE 8
#define SIZEOF_VOID_P 8
#define SIZEOF_SIZE_T 8
#define SIZEOF_TIME_T 8
#define SIZEOF_OFF_T 4
#define SIZEOF_FPOS_T 8
#define SIZEOF_HKEY 8
#define SIZEOF_WCHAR_T 2
#define SIZEOF__BOOL 1
#define HAVE_SSIZE_T 1 /* MinGW-w64's ssize_t is 64 bits, as Py_ssize_t */
#define HAVE_UINTPTR_T 1
#define HAVE_INTPTR_T 1
#define PY_LONG_LONG long long
#define PY_LLONG_MIN LLONG_MIN
#define PY_LLONG_MAX LLONG_MAX
#define PY_ULLONG_MAX ULLONG_MAX
#define HAVE_LARGEFILE_SUPPORT

#define HAVE_COPYSIGN 1
#define HAVE_ROUND 1
#define HAVE_DECL_ISINF 1
#define HAVE_DECL_ISNAN 1
#define HAVE_HYPOT 1
#define HAVE_STRFTIME 1
#define HAVE_DYNAMIC_LOADING 1
#define WITH_PYMALLOC 1
#define WITH_DOC_STRINGS 1
#define STDC_HEADERS 1
#define HAVE_IO_H 1
#define HAVE_DIRECT_H 1
#define HAVE_CONIO_H 1
#define DONT_HAVE_SIG_ALARM
#define DONT_HAVE_SIG_PAUSE

#endif
