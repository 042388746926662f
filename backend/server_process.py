"""How a server process of `dexlabel serve --workers N` ends with the process that started it.

uvicorn's supervisor (the parent) starts N server processes and stops them when it is stopped;
killed outright (kill -9, the out-of-memory killer) it cannot, and its children would go on
serving the port unsupervised, so that the next `dexlabel serve` fails with "Address already
in use". Each child therefore asks to be sent SIGTERM when its parent dies: on Linux the
kernel does it (prctl PR_SET_PDEATHSIG), elsewhere a thread waits on the pipe that the parent
holds open while it lives. uvicorn takes SIGTERM as a request to stop: requests in flight
finish (within `serve`'s grace period), then the process ends.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import multiprocessing
import os
import signal
import sys
import threading
from multiprocessing.connection import wait

PR_SET_PDEATHSIG = 1  # <linux/prctl.h>
# How long (s) a served connection may sit idle before the server closes it. uvicorn's 5 s is
# shorter than the pauses of a worker's page or a requester's boto3 client between calls:
# each such client then reuses a connection the server is closing at that moment, and the
# request is lost unanswered (ConnectionClosedError) unless the client retries. Longer than
# the idle timeout of the proxies and load balancers usually in front (60 s), so a connection
# is closed by them, never under them.
KEEP_ALIVE_S = 75


def exit_with_parent() -> bool:
    """In a process started by multiprocessing (uvicorn's supervisor starts its server processes
    so), have SIGTERM sent to this process once its parent dies; True when armed. Does nothing
    in a process that was not so started (a single `dexlabel serve`, the tests)."""
    parent = multiprocessing.parent_process()
    if parent is None:
        return False
    if sys.platform.startswith("linux"):
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        if libc.prctl(PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0) != 0:
            errno = ctypes.get_errno()
            raise OSError(errno, f"prctl(PR_SET_PDEATHSIG): {os.strerror(errno)}")
    else:
        threading.Thread(target=_stop_when_closed, args=(parent.sentinel,), daemon=True,
                         name="parent-watch").start()
    # A parent that died before the request sends nothing: its pipe is closed already.
    if not parent.is_alive():
        os.kill(os.getpid(), signal.SIGTERM)
    return True


def _stop_when_closed(sentinel: int) -> None:
    """SIGTERM to this process once ``sentinel`` (the parent's end of a pipe) closes."""
    wait([sentinel])
    os.kill(os.getpid(), signal.SIGTERM)
