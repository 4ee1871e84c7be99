"""Parameter studies (``nanomotion sweep``) from Python, on local cores or on Ray.

``engine="local"`` is the Rust path itself (rayon over the local cores).
``engine="ray"`` splits the runs not finished yet into chunks; each chunk is one
Ray task that imports this package in the worker and runs the Rust core
in-process (:func:`run_chunk`). The driver appends each chunk's rows to the
output folder's ``rows.jsonl`` as it arrives — the same store the CLI resumes
from — and writes the same ``results.csv``/``results.parquet``/plots at the end.
A worker lost mid-study fails only its task, which Ray re-runs (``max_retries``);
finished chunks are kept, so an interrupted study resumes where it stopped.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

from . import _nanomotion as _nm


@dataclass(frozen=True)
class SweepSummary:
    """What a sweep did: runs planned, resumed (kept from the folder), computed
    now and failed (rows with an error), files written, wall time (s)."""

    planned: int
    resumed: int
    computed: int
    failed: int
    files: list[str]
    wall_s: float
    out: str
    engine: str

    @property
    def runs_per_s(self) -> float:
        return self.computed / self.wall_s if self.wall_s > 0 else float("nan")


def run_chunk(study: str, indices: Sequence[int], jobs: int = 1) -> str:
    """Run the planned runs ``indices`` of ``study`` in this process (Rust core,
    ``jobs`` threads) and return their rows as JSON: the body of a Ray task."""
    return _nm.sweep_run_chunk(study, list(indices), jobs=jobs)


def _default_out(study: Path) -> Path:
    return Path("out") / f"sweep_{study.stem}"


def sweep(study: str | os.PathLike[str], *, engine: str = "local", out: str | os.PathLike[str] | None = None,
          jobs: int = 0, restart: bool = False, limit: int | None = None, chunk_size: int | None = None,
          max_retries: int = 3, task: Callable[[str, Sequence[int]], str] | None = None) -> SweepSummary:
    """Run the study in ``study`` (a SWEEP.yaml, format in docs/sweep.md).

    ``engine="local"``: ``jobs`` rayon threads (0: all cores), as ``nanomotion
    sweep``. ``engine="ray"``: chunks of ``chunk_size`` runs (default: about four
    chunks per CPU of the Ray cluster) as Ray tasks with ``max_retries`` retries
    on a lost worker; uses the running Ray instance, or starts a local one
    (``ray.init()``) if none is. The study and graph files must be readable at the
    same path on every node. ``task(study, indices) -> rows JSON`` replaces
    :func:`run_chunk` as the task body (for tests that inject failures).

    ``out`` defaults to ``out/sweep_<stem>``; finished rows there are not
    recomputed unless ``restart``; ``limit`` stops after that many runs.
    """
    path = Path(study).resolve()
    out_dir = Path(out) if out is not None else _default_out(path)
    out_dir = out_dir.resolve()
    if engine == "local":
        s = _nm.sweep_local(str(path), str(out_dir), jobs=jobs, restart=restart, limit=limit)
        return SweepSummary(**s, out=str(out_dir), engine="local")
    if engine != "ray":
        raise _nm.SweepError(f"engine `{engine}`: give \"local\" (rayon on this machine) or \"ray\"")
    try:
        import ray
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise _nm.SweepError("engine=\"ray\" needs the `ray` package (fix: pip install ray)") from e
    import time

    # The folder is locked for the whole study, as `nanomotion sweep` does: a
    # second sweep into it (CLI, local or another driver) is refused meanwhile.
    with _nm.sweep_lock(str(out_dir)):
        planned, todo, _hash = _nm.sweep_pending(str(path), str(out_dir), restart=restart)
        resumed = planned - len(todo)
        if limit is not None:
            todo = todo[:limit]
        start = time.perf_counter()
        computed = 0
        if todo:
            if not ray.is_initialized():
                ray.init()
            cpus = max(1, int(ray.cluster_resources().get("CPU", 1)))
            size = chunk_size or max(1, math.ceil(len(todo) / (4 * cpus)))
            chunks = [todo[i:i + size] for i in range(0, len(todo), size)]
            body = task or run_chunk
            remote = ray.remote(num_cpus=1, max_retries=max_retries)(body)
            pending = [remote.remote(str(path), chunk) for chunk in chunks]
            while pending:
                done, pending = ray.wait(pending, num_returns=1)
                for ref in done:
                    computed += _nm.sweep_append(str(path), str(out_dir), ray.get(ref))
        wall = time.perf_counter() - start
        s = _nm.sweep_write(str(path), str(out_dir))
    s.update(resumed=resumed, computed=computed, wall_s=wall)
    return SweepSummary(**s, out=str(out_dir), engine="ray")


def read_results(out: str | os.PathLike[str]) -> list[dict[str, Any]]:
    """The rows of ``out/results.csv`` as dicts of text cells (header order)."""
    import csv

    with open(Path(out) / "results.csv", newline="") as f:
        return list(csv.DictReader(f))
