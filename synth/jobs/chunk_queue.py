"""The local chunk queue of a render job: what may start, what a finished chunk means (shared with
the Ray backend), the progress bar, and the local backend that runs ``workers`` chunk processes at
a time. A failing chunk is retried up to the spec's ``retries`` times, then reported, while the
other chunks go on."""

from __future__ import annotations

import time
from pathlib import Path

from vrformats.fields import terminal_safe

from ..render.chunks import run_chunk_process, stopping_workers
from .estimate import fmt_duration
from .plan import Chunk, Plan
from .state import DONE, FAILED, PENDING, RUNNING, JobState


class ProgressBar:
    """The job's progress bar. With ``eta`` (``synth.jobs.estimate.LiveEta``, the local backend) it shows
    the time left from what each pass kind's frames cost so far, not tqdm's frames-per-second average
    (an RGB frame costs about 100 geometry frames, so that average is wrong by hours)."""

    def __init__(self, total: int, done: int, enabled: bool, desc: str, eta=None):
        from tqdm import tqdm

        fmt = "{l_bar}{bar}| {n_fmt}/{total_fmt} [{elapsed}{postfix}]" if eta is not None else None
        self.bar = tqdm(total=total, initial=done, desc=terminal_safe(desc), unit="frame", disable=not enabled, dynamic_ncols=True,
                        smoothing=0.1, bar_format=fmt)
        self.eta = eta
        self.failures = 0
        self._shown = 0.0

    def update(self, n=1, kind: str | None = None, seconds: float | None = None):
        if self.eta is not None and kind is not None:
            self.eta.frame(kind, seconds)
            self._postfix()
        self.bar.update(n)

    def chunk_started(self, kind: str) -> None:
        if self.eta is not None:
            self.eta.chunk_started(kind)

    def chunk_finished(self, kind: str, wall_s: float, frame_s: float) -> None:
        if self.eta is not None:
            self.eta.chunk_finished(kind, wall_s, frame_s)

    def _postfix(self, force: bool = False) -> None:
        now = time.monotonic()
        if not force and now - self._shown < 1.0:  # at most once a second: this runs on every frame
            return
        self._shown = now
        left, untimed = self.eta.seconds(), self.eta.untimed
        parts = ["ETA " + ("..." if left is None else fmt_duration(left))
                 + (f" + {', '.join(untimed)} frames not timed yet" if untimed and left is not None else "")]
        if self.failures:
            parts.append(f"failures={self.failures}")
        self.bar.set_postfix_str(", ".join(parts), refresh=False)

    def fail(self):
        self.failures += 1
        if self.eta is not None:
            self._postfix(force=True)
            self.bar.refresh()
        else:
            self.bar.set_postfix(failures=self.failures, refresh=True)

    def close(self):
        self.bar.close()


class ChunkQueue:
    """Chunk bookkeeping shared by both backends: what may start, and what a finished chunk means.

    rgb and copy chunks wait for their geometry chunk; a chunk that failed is put back until it has
    had ``retries`` more attempts, then reported failed, and whatever waits on it fails with it."""

    def __init__(self, plan: Plan, state: JobState, todo: list[Chunk], bar: ProgressBar):
        self.spec, self.state, self.bar = plan.spec, state, bar
        self.pending = list(todo)
        self.done = {c.id for c in plan.chunks if c not in todo}
        self.failed: set[str] = set()

    def take_ready(self, limit: int) -> list[Chunk]:
        for c in [c for c in self.pending if c.needs in self.failed]:
            self.pending.remove(c)
            self._fail(c, f"its geometry chunk {c.needs} failed")
        out = []
        for c in list(self.pending):
            if len(out) >= limit:
                break
            if c.needs is None or c.needs in self.done:
                self.pending.remove(c)
                self.state.set(c.id, RUNNING, attempt=True)
                self.bar.chunk_started(c.kind)
                out.append(c)
        return out

    def finished(self, c: Chunk, rc: int, err: str | None, log: str, device: str | None = None) -> bool:
        """Record a chunk's end (and the device it rendered on); True when it is done, False when it
        will be retried or failed."""
        if rc == 0 and not c.missing():
            self.done.add(c.id)
            self.state.set(c.id, DONE, device=device)
            return True
        msg = f"{err or 'frames missing after the chunk ended'} (log: {log})"
        if self.state.doc["chunks"][c.id]["attempts"] <= self.spec.retries:
            self.state.set(c.id, PENDING, msg, device=device)
            self.pending.insert(0, c)
        else:
            self._fail(c, msg, device)
        return False

    def _fail(self, c: Chunk, msg: str, device: str | None = None) -> None:
        self.failed.add(c.id)
        self.state.set(c.id, FAILED, msg, device=device)
        self.bar.fail()


def chunk_files(work: Path, c: Chunk) -> tuple[str, str]:
    base = work / c.id.replace("/", "_")
    return str(base) + ".json", str(base) + ".log"


def run_local(plan: Plan, state: JobState, todo: list[Chunk], workers: int, bar: ProgressBar, work: Path) -> dict:
    """Local backend: ``workers`` chunk processes at a time, each a fresh (Blender) process."""
    import threading
    from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait

    info: dict = {}
    lock = threading.Lock()
    q = ChunkQueue(plan, state, todo, bar)

    frame_s: dict[str, float] = {}  # chunk id -> its frames' own seconds so far

    def on_frame_of(c: Chunk):
        def on_frame(ev):
            s = ev.get("seconds") if isinstance(ev.get("seconds"), (int, float)) else None
            with lock:
                frame_s[c.id] = frame_s.get(c.id, 0.0) + (s or 0.0)
                bar.update(kind=c.kind, seconds=s)
        return on_frame

    with ThreadPoolExecutor(max_workers=workers) as pool, stopping_workers(pool):
        running = {}
        while True:
            for c in q.take_ready(workers - len(running)):
                jf, log = chunk_files(work, c)
                frame_s[c.id] = 0.0
                running[pool.submit(run_chunk_process, c.kind, c.job, jf, log, on_frame_of(c))] = (c, log, time.monotonic())
            if not running:
                break
            finished, _ = wait(running, return_when=FIRST_COMPLETED)
            for fut in finished:
                c, log, t0 = running.pop(fut)
                rc, err, inf = fut.result()
                info.update(inf)
                with lock:
                    bar.chunk_finished(c.kind, time.monotonic() - t0, frame_s.pop(c.id, 0.0))
                q.finished(c, rc, err, log, device=inf.get("device"))
    return info

