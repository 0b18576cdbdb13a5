"""Run each FMU of a job alone with fmpy's ``simulate_fmu`` and save the results (test_windows.py).

    python fmpy_runner.py JOB.json

JOB lists ``{"fmu": path, "stop": stop time, "step": communication step, "out": result.npy}``; each result is
saved with ``numpy.save`` (a structured array: time and the outputs), ``out + ".txt"`` gets the seconds the
run took and ``out + ".log"`` the FMU's messages (logging on).  The same script runs in fmpy for Windows (under wine) and in fmpy on Linux, so the two differ only in
the platform.  A failing FMU writes ``out + ".error"`` with the exception and the others go on.
"""

import json
import sys
import time

if sys.version_info >= (3, 12):
    sys.modules["_wmi"] = None    # Python >= 3.12's platform module calls WMI, which wine 8 lacks (harness only)

import numpy as np                # noqa: E402
from fmpy import simulate_fmu     # noqa: E402


def main(job_file: str) -> None:
    with open(job_file, encoding="utf-8") as file:
        jobs = json.load(file)
    for job in jobs:
        begin = time.perf_counter()
        messages = []

        def logger(environment, instance, status, category, message, messages=messages):
            messages.append(message.decode(errors="replace") if isinstance(message, bytes) else str(message))
        try:
            result = simulate_fmu(job["fmu"], stop_time=job["stop"], output_interval=job["step"],
                                  step_size=job["step"], debug_logging=True, logger=logger)
        except Exception as exc:  # noqa: BLE001 -- reported per FMU, the next one runs
            with open(job["out"] + ".error", "w", encoding="utf-8") as file:
                file.write(f"{type(exc).__name__}: {exc}")
            continue
        np.save(job["out"], result)
        with open(job["out"] + ".log", "w", encoding="utf-8") as file:
            file.write("\n".join(messages))
        with open(job["out"] + ".txt", "w", encoding="utf-8") as file:
            file.write(repr(time.perf_counter() - begin))


if __name__ == "__main__":
    main(sys.argv[1])
