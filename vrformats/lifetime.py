"""Process lifetime, one home for synth and reloc: drivers that stop on a signal, workers that die
with their parent, and one run per output folder.

* **Signals.** ``run_command`` (``vrformats.errors``) runs every CLI command under
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
  long as the run lives, and removes the file when the run ends normally. The kernel drops the lock
  when the process ends, however it ends, so a lock file left by a killed run never blocks; a second
  run into the same folder is refused with one line naming the owner's pid (written into the lock
  file for that message only).
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
from .atomic import open_nofollow

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


_LAST: list[int] = []  # the stop signal received in this command (a library may re-raise it as KeyboardInterrupt)


def _signum(e: KeyboardInterrupt) -> int:
    if isinstance(e, Interrupted):
        return e.signum
    return _LAST[-1] if _LAST else int(signal.SIGINT)


def exit_status(e: KeyboardInterrupt) -> int:
    """``128 + signal``: 130 for Ctrl-C, 143 for SIGTERM, 129 for SIGHUP (also when a library turned
    :class:`Interrupted` into a plain ``KeyboardInterrupt``, as Ray's waits do)."""
    return 128 + _signum(e)


def signal_name(e: KeyboardInterrupt) -> str:
    return signal.Signals(_signum(e)).name


def _raise(signum, _frame):
    _LAST.append(int(signum))
    raise Interrupted(signum)


_ACTIVE = threading.Event()  # inside signals_interrupt


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
    _ACTIVE.set()
    _LAST.clear()
    try:
        yield
    finally:
        _ACTIVE.clear()
        for s, h in old.items():
            signal.signal(s, h)


def reclaim_signals() -> None:
    """Put :func:`signals_interrupt`'s handlers back after a library replaced them (``ray.init`` installs
    its own SIGTERM handler, which prints a stack and kills the driver before it can stop its tasks)."""
    if _ACTIVE.is_set() and threading.current_thread() is threading.main_thread():
        for name in ("SIGTERM", "SIGHUP"):
            s = getattr(signal, name, None)
            if s is not None:
                signal.signal(s, _raise)


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


def child_dies_with_parent() -> None:
    """``preexec_fn`` of a driver started as a child (``reloc bench stability`` runs ``synth render``): the
    kernel sends the child SIGTERM when this process dies, which it turns into its orderly stop (its
    own workers with it)."""
    _set_parent_death_signal(signal.SIGTERM)


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
        fd = open_nofollow(path, os.O_RDWR | os.O_CREAT)  # a planted link or folder is refused in one line
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
        try:  # the file may have been removed by its previous owner after we opened it: lock the current one
            same = os.fstat(fd).st_ino == os.stat(path).st_ino
        except FileNotFoundError:
            same = False
        if not same:
            os.close(fd)
            return self.acquire()
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        self._fd = fd
        return self

    @property
    def held(self) -> bool:
        return self._fd is not None

    def release(self) -> None:
        """Remove the lock file (while still holding it, so no other run can be between) and drop the lock."""
        if self._fd is not None:
            try:
                os.unlink(self.folder / LOCK_FILE)
            except OSError:
                pass
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


# ---------------------------------------------------------------------------------------------
# a reaper for process trees that do not die with their parent by themselves


def _proc_table() -> dict[int, tuple[int, str]]:
    """pid -> (parent pid, start time) of every process, from /proc (Linux)."""
    out = {}
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            fields = (d / "stat").read_text().rsplit(")", 1)[1].split()
            out[int(d.name)] = (int(fields[1]), fields[19])
        except (OSError, IndexError, ValueError):
            continue
    return out


def descendants(pid: int, table: dict | None = None) -> set[int]:
    """Every live process below ``pid`` (children, their children, ...), from /proc (Linux)."""
    table = _proc_table() if table is None else table
    frontier, tree = {pid}, set()
    while frontier:
        kids = {p for p, (pp, _) in table.items() if pp in frontier} - tree
        tree |= kids
        frontier = kids
    return tree


def _reap(driver: int, poll_s: float = 0.5) -> None:
    """The reaper process: every ``poll_s`` it notes the driver's descendants; once the driver is gone
    it stops those still running (SIGTERM, then SIGKILL after 2 s) and exits."""
    me = os.getpid()
    seen: dict[int, str] = {}
    while os.getppid() == driver:
        table = _proc_table()
        seen.update({p: table[p][1] for p in descendants(driver, table) - {me}})
        time.sleep(poll_s)
    table = _proc_table()
    left = [p for p, st in seen.items() if p in table and table[p][1] == st]  # the same processes, not reused pids
    for sig in (signal.SIGTERM, signal.SIGKILL):
        for p in left:
            try:
                os.kill(p, sig)
            except OSError:
                pass
        deadline = time.monotonic() + 2.0
        while time.monotonic() < deadline:
            table = _proc_table()
            left = [p for p in left if p in table and table[p][1] == seen[p]]
            if not left:
                return
            time.sleep(0.1)


def start_reaper() -> "subprocess.Popen | None":
    """Start a reaper for this process's tree (Linux): when this process ends, however it ends, every
    process it started, directly or not, that still runs is stopped. For libraries whose helpers do not
    die with the driver (a local Ray instance's agents outlive a ``kill -9`` of the driver)."""
    import subprocess

    if not Path("/proc/self/stat").exists():
        return None
    code = "import sys; from vrformats.lifetime import _reap; _reap(int(sys.argv[1]))"
    root = str(Path(__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")]))}
    return subprocess.Popen([sys.executable, "-c", code, str(os.getpid())], env=env, stdin=subprocess.DEVNULL,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, close_fds=True)
