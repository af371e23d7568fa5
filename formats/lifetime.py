"""Process lifetime, one home for synth and reloc: drivers that stop on a signal, workers that die
with their parent, and one run per output folder.

* **Signals.** ``run_command`` (``formats.errors``) runs every CLI command under
  :func:`signals_interrupt`: SIGTERM and SIGHUP raise :class:`Interrupted` in the main thread, as
  Ctrl-C raises ``KeyboardInterrupt`` (of which it is a subclass), so that every ``finally`` and
  every ``except KeyboardInterrupt`` of a driver runs for all three. A driver that holds workers
  stops them there (:func:`stop_processes`, ``reloc.experiments.runner``, ``synth.render.chunks``)
  and the command prints one line and exits ``128 + signal`` (130, 143, 129).
* **Workers die with their parent.** A worker process calls :func:`die_with_parent` first thing:
  on Linux the kernel sends it SIGTERM when its parent dies (``PR_SET_PDEATHSIG``), and on any system
  a daemon thread checks every half second that the parent is still its parent (``os.getppid``),
  so a ``kill -9`` of the driver leaves no worker rendering into the void.
* **One run per folder.** :func:`folder_lock` takes an exclusive ``flock`` on ``FOLDER/.lock`` for as
  long as the run lives. The kernel drops it when the process ends, however it ends, so a lock left
  by a killed run never blocks; a second run into the same folder is refused with one line naming
  the owner's pid (written into the lock file for that message only).
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from contextlib import contextmanager
from pathlib import Path

from .errors import UserError

LOCK_FILE = ".lock"
# the signals a driver turns into an orderly stop (Ctrl-C, kill, a closed terminal)
STOP_SIGNALS = ("SIGINT", "SIGTERM", "SIGHUP")


class Interrupted(KeyboardInterrupt):
    """A stop signal other than SIGINT, raised in the main thread; ``exit_status`` is ``128 + signal``."""

    def __init__(self, signum: int):
        self.signum = int(signum)
        super().__init__(signal.Signals(self.signum).name)

    @property
    def exit_status(self) -> int:
        return 128 + self.signum


def exit_status(e: KeyboardInterrupt) -> int:
    """130 for Ctrl-C, ``128 + signal`` for :class:`Interrupted`."""
    return e.exit_status if isinstance(e, Interrupted) else 128 + signal.SIGINT


def signal_name(e: KeyboardInterrupt) -> str:
    return signal.Signals(e.signum).name if isinstance(e, Interrupted) else "SIGINT"


def _raise(signum, _frame):
    raise Interrupted(signum)


@contextmanager
def signals_interrupt():
    """In the main thread: SIGTERM and SIGHUP raise :class:`Interrupted` while the block runs (and the
    previous handlers come back after it). Elsewhere (a worker thread) it does nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = {}
    for name in ("SIGTERM", "SIGHUP"):
        s = getattr(signal, name, None)
        if s is not None:
            old[s] = signal.signal(s, _raise)
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)


# ---------------------------------------------------------------------------------------------
# workers


def _set_parent_death_signal(sig: int) -> bool:
    """Linux's prctl(PR_SET_PDEATHSIG): the kernel sends ``sig`` when the parent dies."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        PR_SET_PDEATHSIG = 1
        return libc.prctl(PR_SET_PDEATHSIG, int(sig), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


PARENT_ENV = "VIDEORELOC_PARENT_PID"  # the pid a worker's starter puts in its environment (worker_env)


def worker_env(env: dict | None = None) -> dict:
    """The environment of a worker process started now (default: this process's), naming this process
    as the parent it must die with (:func:`die_with_parent`)."""
    return {**(os.environ if env is None else env), PARENT_ENV: str(os.getpid())}


def die_with_parent(parent: int | None = None, poll_s: float = 0.5) -> None:
    """Make this worker process end when its parent does (call it first thing in a worker).

    ``parent``: the pid expected as parent (default: ``$VIDEORELOC_PARENT_PID`` set by
    :func:`worker_env`, else the current parent). A worker whose parent died while it was starting
    (it has been reparented already) exits at once."""
    if parent is None:
        parent = int(os.environ.get(PARENT_ENV) or os.getppid())
    parent = int(parent)
    _set_parent_death_signal(signal.SIGTERM)
    if os.getppid() != parent:  # the parent died before the kernel was told
        os._exit(128 + signal.SIGTERM)

    def watch():
        while True:
            time.sleep(poll_s)
            if os.getppid() != parent:
                os._exit(128 + signal.SIGTERM)

    threading.Thread(target=watch, name="die-with-parent", daemon=True).start()


def ignore_interrupts() -> None:
    """In a pool worker: leave Ctrl-C of the whole process group to the driver, which stops the workers
    itself (no traceback per worker)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def worker_init(parent: int | None = None) -> None:
    """``initializer=`` of a process pool, with ``initargs=(os.getpid(),)``: the worker dies with its
    parent (also one that died while the worker was starting) and leaves Ctrl-C to it."""
    die_with_parent(parent)
    ignore_interrupts()


def stop_processes(procs, grace_s: float = 3.0) -> int:
    """SIGTERM to every live process of ``procs`` (``subprocess.Popen`` or ``multiprocessing.Process``),
    SIGKILL to those still alive after ``grace_s``; returns how many were alive."""
    live = [p for p in procs if _alive(p)]
    for p in live:
        try:
            p.terminate()
        except (OSError, ProcessLookupError):
            pass
    deadline = time.monotonic() + grace_s
    for p in live:
        while _alive(p) and time.monotonic() < deadline:
            time.sleep(0.05)
        if _alive(p):
            try:
                p.kill()
            except (OSError, ProcessLookupError):
                pass
    for p in live:  # reap them
        try:
            p.wait(1.0) if hasattr(p, "wait") else p.join(1.0)
        except Exception:  # noqa: BLE001 - a process that will not be reaped is the kernel's now
            pass
    return len(live)


def _alive(p) -> bool:
    if hasattr(p, "poll"):
        return p.poll() is None
    return p.is_alive()


# ---------------------------------------------------------------------------------------------
# one run per folder


class FolderLock:
    """An exclusive ``flock`` on ``FOLDER/.lock``, held until :meth:`release` or the process ends."""

    def __init__(self, folder, what: str):
        self.folder = Path(folder)
        self.what = what
        self._fd: int | None = None

    def acquire(self) -> "FolderLock":
        import fcntl

        self.folder.mkdir(parents=True, exist_ok=True)
        path = self.folder / LOCK_FILE
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            try:
                owner = os.pread(fd, 64, 0).decode("ascii", "replace").strip() or "unknown"
            except OSError:
                owner = "unknown"
            os.close(fd)
            raise UserError(f"{self.folder}: another {self.what} is running in this folder (pid {owner}); wait for it "
                            "to finish or stop it, or use another output folder") from None
        except OSError as e:  # a file system without locks: say so rather than run unprotected silently
            os.close(fd)
            raise UserError(f"{path}: cannot lock the output folder ({e.strerror or e})") from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        self._fd = fd
        return self

    def release(self) -> None:
        if self._fd is not None:
            os.close(self._fd)  # closing the descriptor drops the flock
            self._fd = None

    def __enter__(self) -> "FolderLock":
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()


def folder_lock(folder, what: str) -> FolderLock:
    """``with folder_lock(out, "synth render"):``: refuse a second run into ``folder`` (one line, the
    owner's pid); the folder is created if needed."""
    return FolderLock(folder, what)
