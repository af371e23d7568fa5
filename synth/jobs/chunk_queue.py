"""The local chunk queue of a render job: what may start, what a finished chunk means (shared with
the Ray backend), the progress bar, and the local backend that runs ``workers`` chunk processes at
a time. A failing chunk is retried up to the spec's ``retries`` times, then reported, while the
other chunks go on."""

from __future__ import annotations

from pathlib import Path

from vrformats.fields import terminal_safe

from ..render.chunks import run_chunk_process, stopping_workers
from .plan import Chunk, Plan
from .state import DONE, FAILED, PENDING, RUNNING, JobState


class ProgressBar:
    def __init__(self, total: int, done: int, enabled: bool, desc: str):
        from tqdm import tqdm

        self.bar = tqdm(total=total, initial=done, desc=terminal_safe(desc), unit="frame", disable=not enabled, dynamic_ncols=True,
                        smoothing=0.1)
        self.failures = 0

    def update(self, n=1):
        self.bar.update(n)

    def fail(self):
        self.failures += 1
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

    def on_frame(_ev):
        with lock:
            bar.update()

    with ThreadPoolExecutor(max_workers=workers) as pool, stopping_workers(pool):
        running = {}
        while True:
            for c in q.take_ready(workers - len(running)):
                jf, log = chunk_files(work, c)
                running[pool.submit(run_chunk_process, c.kind, c.job, jf, log, on_frame)] = (c, log)
            if not running:
                break
            finished, _ = wait(running, return_when=FIRST_COMPLETED)
            for fut in finished:
                c, log = running.pop(fut)
                rc, err, inf = fut.result()
                info.update(inf)
                q.finished(c, rc, err, log, device=inf.get("device"))
    return info

