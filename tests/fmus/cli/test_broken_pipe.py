"""A reader that goes away (``obsfmu show --fields | head -1``) ends obsfmu quietly, as SIGPIPE would."""

from __future__ import annotations

import os
import signal
import subprocess
import sys


def test_a_closed_standard_output_is_no_error_message_and_exits_as_sigpipe():
    read_end, write_end = os.pipe()
    os.close(read_end)                          # the reader is gone before the first line is written
    try:
        process = subprocess.run([sys.executable, "-m", "obsfmu", "show", "--fields"], stdout=write_end,
                                 stderr=subprocess.PIPE, text=True, timeout=120)
    finally:
        os.close(write_end)
    assert process.returncode == 128 + signal.SIGPIPE, process.stderr
    assert process.stderr == ""
