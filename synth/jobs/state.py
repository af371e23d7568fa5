"""A render job's state file, ``OUT/job_state.json``: each chunk's state (``PENDING``, ``RUNNING``,
``DONE``, ``FAILED`` with its error and attempts), rewritten atomically after every change.

The frames on disk are the truth about what is done: a chunk is done when all its frame files
exist, and they appear only once complete. So after the runner is killed, ``--resume`` renders
exactly what is missing; the state file keeps the attempts and the devices across runs.
"""

from __future__ import annotations

import json
from pathlib import Path

from vrformats.atomic import write_text_atomic
from vrformats.errors import UserError, one_line

from .plan import Chunk

STATE_FILE = "job_state.json"
PENDING, RUNNING, DONE, FAILED = "pending", "running", "done", "failed"
CHUNK_STATES = (PENDING, RUNNING, DONE, FAILED)


class JobState:
    """``job_state.json``: chunk id -> {state, attempts, error, frames}; rewritten atomically."""

    def __init__(self, path: Path, chunks: list[Chunk], spec_doc: dict, store=None):
        self.path = path
        self.store = store  # synth.jobs.storage.Storage: every save is copied up
        self.doc = {"spec": spec_doc, "chunks": {c.id: {"state": PENDING, "attempts": 0, "error": None,
                                                        "frames": [c.frames[0], c.frames[-1]], "devices": []}
                                                 for c in chunks}}

    @staticmethod
    def load(path: Path) -> dict | None:
        """The state document in the job folder ``path`` points into, or None before the first run."""
        if not path.exists():
            return None
        try:
            text = path.read_text()
        except (OSError, UnicodeDecodeError) as e:
            raise UserError(f"{path}: unreadable job state ({one_line(e)}); delete it to start the job afresh") from None
        return parse_state(text, str(path))

    def merge(self, old: dict) -> None:
        for cid, st in (old or {}).get("chunks", {}).items():
            if cid in self.doc["chunks"]:
                self.doc["chunks"][cid]["attempts"] = st.get("attempts", 0)
                self.doc["chunks"][cid]["devices"] = sorted(set(st.get("devices") or []))

    def set(self, cid: str, state: str, error: str | None = None, attempt: bool = False, device: str | None = None) -> None:
        c = self.doc["chunks"][cid]
        if device:  # the device a worker reported rendering on (``ready`` event), over every attempt
            c["devices"] = sorted(set(c.get("devices") or []) | {device})
        c["state"] = state
        c["error"] = error
        if attempt:
            c["attempts"] += 1
        self.save()

    def save(self) -> None:
        text = json.dumps(self.doc, indent=1)
        write_text_atomic(self.path, text)
        if self.store is not None:
            self.store.write_text(self.path, text)

    def devices(self, chunks: list[Chunk]) -> dict:
        """Pass -> the devices its chunks reported (sorted), for the passes that rendered anything."""
        out: dict[str, set] = {}
        for c in chunks:
            devs = self.doc["chunks"][c.id].get("devices") or []
            if devs:
                out.setdefault(c.kind, set()).update(devs)
        return {k: sorted(v) for k, v in sorted(out.items())}

    def counts(self) -> dict:
        out: dict[str, int] = {}
        for c in self.doc["chunks"].values():
            out[c["state"]] = out.get(c["state"], 0) + 1
        return out


def parse_state(text: str, where: str) -> dict:
    """A job state document from its text (a folder's or a storage's ``job_state.json``): a JSON
    object, else one line naming ``where`` and what to do."""
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as e:
        problem = f"not valid JSON: {e.msg} at line {e.lineno}"
    except RecursionError:
        problem = "nested too deeply"  # (vrformats.yamlfile bounds the files users hand it; this one the toolkit wrote)
    else:
        if isinstance(doc, dict):
            return doc
        problem = f"expected a JSON object, got {type(doc).__name__}"
    raise UserError(f"{where}: unreadable job state ({problem}); delete it to start the job afresh")


def load_stored_state(store) -> dict | None:
    """The state document of a job folder on a storage (``synth.jobs.storage``), or None before the first run."""
    try:
        text = store.read_text(STATE_FILE)
    except FileNotFoundError:
        return None
    except UnicodeDecodeError as e:
        raise UserError(f"{store.url(STATE_FILE)}: unreadable job state ({one_line(e)}); delete it to start the job "
                        "afresh") from None
    return parse_state(text, store.url(STATE_FILE))
