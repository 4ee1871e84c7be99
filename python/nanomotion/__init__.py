"""nanomotion from Python: performance-driven control of nano-motion systems.

The Rust library behind the ``nanomotion`` command, in-process:

>>> import nanomotion as nm
>>> r = nm.run("examples/quickstart.yaml", duration=0.5)      # doctest: +SKIP
>>> r.scores["err.y"].rms, r.signals["stage.y"]                # doctest: +SKIP

- graphs: :func:`load`, :func:`check` (the stability gate), :func:`run`
  (overrides by dotted path, seed, duration, measured data; signals as numpy
  arrays, scores), :func:`rt` (the same on the wall clock, alone or against
  a plant in another process, with its timing report) and :func:`rt_start`
  (in the background, with live parameter updates), :func:`diagnose` (name what a model misses),
  :func:`compensate` (compensate what it named in a controller graph);
- studies: :func:`sweep` over a SWEEP.yaml, on local cores or on Ray;
- analysis: :func:`psd_welch`, :func:`cumulative_psd`, :func:`frf_h1`,
  :class:`Lti` (frequency response, poles, H∞ norm, margins);
- models: :class:`ColemanHodgdon` hysteresis and :class:`HysteresisInverse`
  (thesis (6.3), (6.4), (6.6)); :class:`TimestampEstimator` and
  :func:`timestamp_track` (thesis Ch. 8).

Every error is a :class:`NanomotionError` (subclasses per area) carrying the
Rust library's message unchanged.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence, Union

import numpy as np

from . import _nanomotion as _nm
from ._nanomotion import (
    AnalysisError,
    ColemanHodgdon,
    DataError,
    DiagnoseError,
    GateError,
    GraphError,
    HysteresisInverse,
    Lti,
    ModelError,
    NanomotionError,
    SweepError,
    TimestampEstimator,
    cumulative_psd,
    frf_h1,
    psd_welch,
    timestamp_track as _timestamp_track,
)

from ._sweep import SweepSummary, read_results, run_chunk, sweep

__version__: str = _nm.__version__

PathLike = Union[str, "os.PathLike[str]"]

__all__ = [
    "AnalysisError",
    "CheckResult",
    "ColemanHodgdon",
    "DataError",
    "DiagnoseError",
    "DiagnoseResult",
    "GateError",
    "Graph",
    "GraphError",
    "HysteresisInverse",
    "Lti",
    "ModelError",
    "NanomotionError",
    "RtResult",
    "RtRun",
    "RunResult",
    "Score",
    "SweepError",
    "SweepSummary",
    "TimestampEstimator",
    "CompensateResult",
    "check",
    "compensate",
    "cumulative_psd",
    "diagnose",
    "frf_h1",
    "load",
    "psd_welch",
    "read_results",
    "rt",
    "rt_start",
    "run",
    "run_chunk",
    "sweep",
    "timestamp_track",
]


@dataclass(frozen=True)
class Score:
    """Score of one ``score:`` signal (the CLI's metrics table row)."""

    rms: float
    max_abs: float
    mean: float
    from_s: float
    samples: int
    unit: str | None


@dataclass
class RunResult:
    """What a run produced: logged signals as numpy arrays and the scores."""

    title: str | None
    duration_s: float
    wall_s: float
    signals: dict[str, np.ndarray]
    rates_hz: dict[str, float]
    units: dict[str, str | None]
    scores: dict[str, Score]
    comparisons: list[dict[str, Any]] = field(default_factory=list)
    stability_gate: list[str] = field(default_factory=list)

    def time(self, signal: str) -> np.ndarray:
        """Sample times (s) of a logged signal: t_i = i / rate."""
        n = self.signals[signal].shape[0]
        return np.arange(n) / self.rates_hz[signal]


@dataclass
class RtResult(RunResult):
    """A run on the wall clock: what :class:`RunResult` holds, and ``timing``,
    the loop's timing report (``timing.json`` of ``nanomotion rt --out``:
    ``ticks``, ``overruns``, ``missed_ticks``, ``scheduling``, ``stop``, and
    the ``wakeup_latency`` / ``period_jitter`` / ``execution`` summaries with
    ``p50_ns``, ``p99_ns``, ``p999_ns``, ``max_ns``; docs/realtime.md)."""

    timing: dict[str, Any] = field(default_factory=dict)


class RtRun:
    """A graph running on the wall clock in the background (:func:`rt_start`).

    ``set("pi.kp", 4e7)`` changes a live parameter at the loop's next tick
    boundary, judged first exactly as ``set pi.kp=4e7`` on ``nanomotion rt``'s
    standard input is (the block's validation, then the stability gate on a
    copy of the graph): a refusal raises :class:`GraphError` (no such live
    parameter, a value the block refuses) or :class:`GateError` (a loop that
    passes would fail), naming the parameter and the fix, and nothing reaches
    the loop. ``status()`` reports the ticks so far and every update applied
    with the tick it took effect at. ``wait()`` lets the loop run its
    duration, ``stop()`` ends it at the next tick boundary (outputs safe); both
    return the :class:`RtResult` (the same object on later calls, also as
    ``result``). As a context manager it waits at the end of the ``with``
    block, or stops the loop if the block raised.
    """

    def __init__(self, run: "_nm.RtRun") -> None:
        self._run = run
        self._result: RtResult | None = None

    @property
    def live_params(self) -> list[str]:
        """The graph's parameters that can change while it runs (``BLOCK.PARAM``)."""
        return self._run.live_params

    @property
    def device(self) -> str:
        """The device the loop drives: ``"none"`` or ``"shm:NAME"``."""
        return self._run.device

    @property
    def running(self) -> bool:
        """Whether the loop still runs."""
        return self._run.running

    def set(self, path: str, value: float | str) -> None:
        """Set live parameter ``path`` (``"pi.kp"`` or ``"blocks.pi.kp"``) to
        ``value`` (a number, or the text of one) at the next tick boundary."""
        self._run.set(path, value)

    def status(self) -> dict[str, Any]:
        """``running``, ``device``, ``ticks`` and ``t_s`` (at the loop's last
        status, every 0.1 s of ticks), ``overruns``,
        ``worst_wakeup_latency_ns``, ``worst_execution_ns``, and ``updates``:
        each update applied as ``{"path", "value", "tick", "t_s"}``, ``tick``
        the first tick computed with the new value."""
        return self._run.status()

    def _finish(self, stop: bool) -> RtResult:
        if self._result is not None:
            return self._result
        r, timing = self._run.stop() if stop else self._run.wait()
        r["scores"] = {k: Score(**v) for k, v in r["scores"].items()}
        self._result = RtResult(**r, timing=json.loads(timing))
        return self._result

    def wait(self) -> RtResult:
        """Wait until the loop has run its duration (Ctrl-C stops it)."""
        return self._finish(stop=False)

    def stop(self) -> RtResult:
        """Stop the loop at its next tick boundary, outputs safe
        (``timing["stop"] == "interrupted"`` if it had not ended already)."""
        return self._finish(stop=True)

    @property
    def result(self) -> RtResult | None:
        """The run, once :meth:`wait` or :meth:`stop` returned it."""
        return self._result

    def __enter__(self) -> "RtRun":
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if exc_type is None:
            self.wait()
        else:
            self.stop()

    def __repr__(self) -> str:
        return f"RtRun(device={self.device!r}, running={self.running})"


@dataclass(frozen=True)
class CheckResult:
    """The stability gate's verdict on a graph (``nanomotion check``)."""

    passes: bool
    report: str
    failures: list[str]
    allowed: list[str]
    order: list[str]
    rate_transitions: list[str]
    base_rate_hz: float
    ticks: int

    def __str__(self) -> str:
        return self.report

    def __bool__(self) -> bool:
        return self.passes


@dataclass(frozen=True)
class DiagnoseResult:
    """``nanomotion diagnose``'s result: the JSON report as a dict (the CLI's
    ``report.json``) and the augmented graph's YAML (``model_augmented.yaml``,
    None when nothing was found)."""

    report: dict[str, Any]
    augmented_yaml: str | None

    @property
    def found(self) -> list[str]:
        """The effects named, in order."""
        return list(self.report.get("found", []))


@dataclass(frozen=True)
class CompensateResult:
    """``nanomotion compensate``'s result: the JSON report as a dict (the CLI's
    ``report.json``) and the compensated graph's YAML (``compensated.yaml``)."""

    report: dict[str, Any]
    compensated_yaml: str

    @property
    def kept(self) -> list[str]:
        """The compensator blocks in the compensated graph."""
        return [c["block"] for c in self.report.get("compensators", []) if c["kept"]]


class Graph:
    """A YAML controller graph, from a file or from text.

    ``Graph("g.yaml")`` or ``Graph(yaml=text)``. Relative parameter files in a
    graph read from a file resolve against the file's folder, as for the CLI.
    """

    def __init__(self, path: PathLike | None = None, *, yaml: str | None = None,
                 origin: str = "<string>", overrides: Mapping[str, Any] | None = None) -> None:
        if (path is None) == (yaml is None):
            raise GraphError("give a graph either as a file path or as YAML text, not both or neither")
        self.path: str | None = None if path is None else os.fspath(path)
        self.yaml: str | None = yaml
        self.origin: str = origin if path is None else self.path  # type: ignore[assignment]
        self.overrides: dict[str, Any] = dict(overrides or {})
        info = _nm.load_graph(**self._source())
        self.title: str | None = info["title"]
        self.base_rate_hz: float = info["base_rate_hz"]
        self.duration_s: float = info["duration_s"]
        self.seed: int = info["seed"]
        self.blocks: list[tuple[str, str]] = [tuple(b) for b in info["blocks"]]  # type: ignore[misc]
        self.log: list[str] = info["log"]
        self.score: list[str] = info["score"]

    def _source(self, extra: Mapping[str, Any] | None = None) -> dict[str, Any]:
        merged = {**self.overrides, **dict(extra or {})}
        return {"path": self.path, "text": self.yaml, "origin": self.origin,
                "overrides": _override_pairs(merged)}

    def with_overrides(self, overrides: Mapping[str, Any]) -> "Graph":
        """The same graph with more dotted-path overrides (later ones win)."""
        return Graph(self.path, yaml=self.yaml, origin=self.origin,
                     overrides={**self.overrides, **dict(overrides)})

    def check(self) -> CheckResult:
        """Build the graph and analyse every feedback loop (the stability gate)."""
        return CheckResult(**_nm.check_graph(**self._source()))

    def run(self, overrides: Mapping[str, Any] | None = None, *, seed: int | None = None,
            duration: float | None = None, data: PathLike | Sequence[PathLike] | None = None,
            data_rate: float | None = None, allow_unproven: bool = False) -> RunResult:
        """Run the graph (``nanomotion run`` without files). See :func:`run`."""
        if data is None:
            files: list[str] = []
        elif isinstance(data, (str, os.PathLike)):
            files = [os.fspath(data)]
        else:
            files = [os.fspath(d) for d in data]
        r = _nm.run_graph(**self._source(overrides), seed=seed, duration=duration,
                          data=files, data_rate=data_rate, allow_unproven=allow_unproven)
        r["scores"] = {k: Score(**v) for k, v in r["scores"].items()}
        return RunResult(**r)

    def rt(self, overrides: Mapping[str, Any] | None = None, *, duration: float | None = None,
           allow_unproven: bool = False, allow_soft: bool = False, priority: int = 80,
           cpu: int | None = None, overrun: str | None = None, max_overruns: int | None = None,
           allow_idle_states: bool = False, device: str | None = None,
           connect_timeout: float = 10.0, watchdog_ms: float = 50.0) -> RtResult:
        """Run the graph on the wall clock (``nanomotion rt`` without files). See :func:`rt`."""
        return self.rt_start(overrides, duration=duration, allow_unproven=allow_unproven,
                             allow_soft=allow_soft, priority=priority, cpu=cpu, overrun=overrun,
                             max_overruns=max_overruns, allow_idle_states=allow_idle_states,
                             device=device, connect_timeout=connect_timeout,
                             watchdog_ms=watchdog_ms).wait()

    def rt_start(self, overrides: Mapping[str, Any] | None = None, *,
                 duration: float | None = None, allow_unproven: bool = False,
                 allow_soft: bool = False, priority: int = 80, cpu: int | None = None,
                 overrun: str | None = None, max_overruns: int | None = None,
                 allow_idle_states: bool = False, device: str | None = None,
                 connect_timeout: float = 10.0, watchdog_ms: float = 50.0) -> "RtRun":
        """Start the graph on the wall clock in the background. See :func:`rt_start`."""
        return RtRun(_nm.rt_start(**self._source(overrides), duration=duration,
                                  allow_unproven=allow_unproven, allow_soft=allow_soft,
                                  priority=priority, cpu=cpu, overrun=overrun,
                                  max_overruns=max_overruns, allow_idle_states=allow_idle_states,
                                  device=device, connect_timeout=connect_timeout,
                                  watchdog_ms=watchdog_ms))

    def __repr__(self) -> str:
        return f"Graph({self.origin!r}, {len(self.blocks)} blocks, {self.duration_s} s at {self.base_rate_hz} Hz)"


def _override_pairs(overrides: Mapping[str, Any]) -> list[tuple[str, str]]:
    """(dotted path, value as YAML text): JSON is YAML, so json.dumps writes it."""
    out = []
    for path, value in overrides.items():
        if isinstance(value, np.generic):
            value = value.item()
        elif isinstance(value, np.ndarray):
            value = value.tolist()
        out.append((str(path), json.dumps(value)))
    return out


def _graph(graph: PathLike | Graph) -> Graph:
    return graph if isinstance(graph, Graph) else Graph(graph)


def load(path: PathLike) -> Graph:
    """Read and validate a graph file (YAML schema, block types); raises
    :class:`GraphError` with the file, line and column."""
    return Graph(path)


def check(graph: PathLike | Graph, overrides: Mapping[str, Any] | None = None) -> CheckResult:
    """The stability gate's verdict on a graph (``nanomotion check``): closed-loop
    poles, margins, ‖S‖∞, ‖T‖∞ of every loop; ``passes`` is False when a loop is
    unstable, unproven without a stated reason, or misses a ``require:`` bound."""
    g = _graph(graph)
    return (g.with_overrides(overrides) if overrides else g).check()


def run(graph: PathLike | Graph, overrides: Mapping[str, Any] | None = None, *,
        seed: int | None = None, duration: float | None = None,
        data: PathLike | Sequence[PathLike] | None = None, data_rate: float | None = None,
        allow_unproven: bool = False) -> RunResult:
    """Run a graph as ``nanomotion run`` does, keeping the logs in memory.

    ``overrides`` sets parameters by dotted path before the graph is built
    (``{"blocks.pi.kp": 2e7, "blocks.stage.den.0": 0.3}``, as ``nanomotion run
    --set``); a wrong path raises :class:`GraphError` naming the nearest key.
    ``seed`` and ``duration`` (s) override the graph's; ``data`` is a measured
    record (CSV with ``t_s``, or MATLAB v5 ``.mat``; a list merges files) played
    by ``data_column`` blocks and compared with ``compare:`` signals (the duration
    becomes the data's unless given). Raises :class:`GateError` when the stability
    gate refuses the graph, unless ``allow_unproven``.
    """
    return _graph(graph).run(overrides, seed=seed, duration=duration, data=data,
                             data_rate=data_rate, allow_unproven=allow_unproven)


def rt(graph: PathLike | Graph, overrides: Mapping[str, Any] | None = None, *,
       duration: float | None = None, allow_unproven: bool = False, allow_soft: bool = False,
       priority: int = 80, cpu: int | None = None, overrun: str | None = None,
       max_overruns: int | None = None, allow_idle_states: bool = False,
       device: str | None = None, connect_timeout: float = 10.0,
       watchdog_ms: float = 50.0) -> RtResult:
    """Run a graph on the wall clock as ``nanomotion rt GRAPH [--device
    shm:NAME]`` does, keeping the logs in memory (:func:`rt_start`, then
    :meth:`RtRun.wait`).

    The stability gate judges the graph first (:class:`GateError` unless
    ``allow_unproven``). Without ``device`` the loop closes inside the graph
    (a graph with ``hw_input``/``hw_output`` blocks is refused); with
    ``device="shm:NAME"`` its ``hw_input``/``hw_output`` blocks are the
    channels of a plant served by ``nanomotion plant PLANT.yaml --serve NAME``
    (waiting up to ``connect_timeout`` s for it; the loop stops when the plant
    is silent for ``watchdog_ms``), and the stability gate then judges the
    loop through it — the plant's graph joined to this one with the device's
    latency of one tick — refusing a loop whose margin the latency eats. The loop thread runs SCHED_FIFO at
    ``priority`` (pinned to ``cpu``), with memory locked and the CPUs held out
    of deep idle states (unless ``allow_idle_states``); where a privilege is
    refused the run is refused, or runs at normal priority with
    ``allow_soft``. ``overrun`` is ``"skip"`` (stay on the grid, count missed
    ticks) or ``"catch-up"`` (run late ticks back to back: every tick runs, so
    the logs equal :func:`run`'s); the default is the graph's ``realtime:``
    section, else ``"skip"``. The loop stops, outputs safe, after more than
    ``max_overruns``, or when the device fails (``timing["stop"]`` says why).
    The GIL is released while the loop runs. See docs/realtime.md.
    """
    return _graph(graph).rt(overrides, duration=duration, allow_unproven=allow_unproven,
                            allow_soft=allow_soft, priority=priority, cpu=cpu, overrun=overrun,
                            max_overruns=max_overruns, allow_idle_states=allow_idle_states,
                            device=device, connect_timeout=connect_timeout,
                            watchdog_ms=watchdog_ms)


def rt_start(graph: PathLike | Graph, overrides: Mapping[str, Any] | None = None, *,
             duration: float | None = None, allow_unproven: bool = False,
             allow_soft: bool = False, priority: int = 80, cpu: int | None = None,
             overrun: str | None = None, max_overruns: int | None = None,
             allow_idle_states: bool = False, device: str | None = None,
             connect_timeout: float = 10.0, watchdog_ms: float = 50.0) -> RtRun:
    """Start a graph on the wall clock in the background, as :func:`rt` runs
    it (same arguments), and return its :class:`RtRun` at once: change live
    parameters while it runs (``h.set("pi.kp", 4e7)``), watch it
    (``h.status()``), end it (``h.wait()`` / ``h.stop()`` return the
    :class:`RtResult`). Everything :func:`rt` refuses is refused here, before
    the loop starts.

    >>> with nm.rt_start("examples/quickstart.yaml", duration=2.0) as h:  # doctest: +SKIP
    ...     time.sleep(0.5)
    ...     h.set("pi.kp", 4e7)
    >>> h.result.timing["param_updates"]                                     # doctest: +SKIP
    1
    """
    return _graph(graph).rt_start(overrides, duration=duration, allow_unproven=allow_unproven,
                                  allow_soft=allow_soft, priority=priority, cpu=cpu,
                                  overrun=overrun, max_overruns=max_overruns,
                                  allow_idle_states=allow_idle_states, device=device,
                                  connect_timeout=connect_timeout, watchdog_ms=watchdog_ms)


def diagnose(model: PathLike, data: PathLike, *, max_effects: int = 3, holdout: float = 0.3,
             seed: int | None = None, effects: Sequence[str] = (),
             validation: Sequence[PathLike] = (), phase: str | None = None) -> DiagnoseResult:
    """Name what a model graph misses against a measured record, fit it, and
    return the report and the augmented graph (``nanomotion diagnose``). With
    ``validation`` records, ``data`` estimates and they decide (each record
    simulated from rest); without, the last ``holdout`` of ``data`` decides.
    ``phase`` (``--phase``) is a signal of the model, ``"BLOCK.PORT"`` such as
    ``"alpha.y"`` (a walking drive's leg angle), that a disturbance may be
    periodic in: one on the drive periodic in it is tried, its period found
    from the data."""
    js, yaml = _nm.diagnose_graph(os.fspath(model), os.fspath(data), max_effects=max_effects,
                                  holdout=holdout, seed=seed, effects=list(effects),
                                  validation=[os.fspath(v) for v in validation], phase=phase)
    return DiagnoseResult(report=json.loads(js), augmented_yaml=yaml)


def compensate(augmented: PathLike, controller: PathLike, *, report: PathLike | None = None,
               reference: PathLike | None = None, keep: bool = False,
               measured_alpha: PathLike | Sequence[PathLike] = (),
               delay_margin: float | None = None) -> CompensateResult:
    """Compensate the effects a diagnosis named (``model_augmented.yaml`` and its
    ``report.json``) in a controller graph, validated on the augmented model
    (``nanomotion compensate``; docs/compensate.md).

    For delay-varying RC, ``measured_alpha`` is a record (or several) of the
    signal the disturbance is periodic in, from your loop on the stage without
    RC, as ``"FILE[:COLUMN]"`` — the same as the CLI's ``--measured-alpha``;
    ``delay_margin`` widens the delay range [m, M] on each side (default: as
    ``--delay-margin``; the report's ``delay_margin`` is the one used)."""
    if isinstance(measured_alpha, (str, os.PathLike)):
        measured_alpha = [measured_alpha]
    js, yaml = _nm.compensate_graph(
        os.fspath(augmented), os.fspath(controller),
        report=None if report is None else os.fspath(report),
        reference=None if reference is None else os.fspath(reference), keep=keep,
        measured_alpha=[os.fspath(m) for m in measured_alpha], delay_margin=delay_margin)
    return CompensateResult(report=json.loads(js), compensated_yaml=yaml)


def timestamp_track(t: np.ndarray, x: np.ndarray, v: np.ndarray, a: np.ndarray | None = None, *,
                    encoder: Mapping[str, Any] | None = None, order: int = 2,
                    fallback: str = "thesis", seed: int = 0
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """An encoder with time-stamped events read along a known trajectory, then
    the time-stamping estimator (thesis Ch. 8).

    ``encoder`` holds the ``timestamp_encoder`` block's parameters (``lines``,
    ``clock_hz``, ``register_len``, ``skip``, slit errors, ...). Returns the
    (N, 3) estimates [x̂, v̂, â], the (N,) status (0 fitted, 1 out of band, 2 no
    events, 3 standstill), the count times the resolution, and the (N, 2+2n)
    registers.
    """
    f = lambda z: None if z is None else np.ascontiguousarray(z, dtype=float)  # noqa: E731
    return _timestamp_track(f(t), f(x), f(v), f(a), encoder_json=json.dumps(dict(encoder or {})),
                            order=order, fallback=fallback, seed=seed)
