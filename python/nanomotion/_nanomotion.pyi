"""Type stubs of the extension module nanomotion._nanomotion (Rust, pyo3)."""

from os import PathLike
from typing import Any

import numpy as np
import numpy.typing as npt

__version__: str

class NanomotionError(Exception): ...
class GraphError(NanomotionError): ...
class GateError(NanomotionError): ...
class DataError(NanomotionError): ...
class AnalysisError(NanomotionError): ...
class ModelError(NanomotionError): ...
class DiagnoseError(NanomotionError): ...
class SweepError(NanomotionError): ...

_Path = str | PathLike[str]
_F64 = npt.NDArray[np.float64]
_C128 = npt.NDArray[np.complex128]

def load_graph(
    path: _Path | None = None, text: str | None = None, origin: str = "<string>", overrides: list[tuple[str, str]] = ...
) -> dict[str, Any]: ...
def check_graph(
    path: _Path | None = None, text: str | None = None, origin: str = "<string>", overrides: list[tuple[str, str]] = ...
) -> dict[str, Any]: ...
def run_graph(
    path: _Path | None = None,
    text: str | None = None,
    origin: str = "<string>",
    overrides: list[tuple[str, str]] = ...,
    seed: int | None = None,
    duration: float | None = None,
    data: list[_Path] = ...,
    data_rate: float | None = None,
    allow_unproven: bool = False,
) -> dict[str, Any]: ...
class RtRun:
    """A loop running in the background (see nanomotion.rt_start)."""

    @property
    def live_params(self) -> list[str]: ...
    @property
    def device(self) -> str: ...
    @property
    def running(self) -> bool: ...
    def set(self, path: str, value: float | str) -> None: ...
    def status(self) -> dict[str, Any]: ...
    def wait(self) -> tuple[dict[str, Any], str]: ...
    def stop(self) -> tuple[dict[str, Any], str]: ...

def rt_start(
    path: _Path | None = None,
    text: str | None = None,
    origin: str = "<string>",
    overrides: list[tuple[str, str]] = ...,
    duration: float | None = None,
    allow_unproven: bool = False,
    allow_soft: bool = False,
    priority: int = 80,
    cpu: int | None = None,
    overrun: str | None = None,
    max_overruns: int | None = None,
    allow_idle_states: bool = False,
    device: str | None = None,
    connect_timeout: float = 10.0,
    watchdog_ms: float = 50.0,
) -> RtRun: ...
def diagnose_graph(
    model: _Path,
    data: _Path,
    max_effects: int = 3,
    holdout: float = 0.3,
    seed: int | None = None,
    effects: list[str] = ...,
    validation: list[_Path] = ...,
) -> tuple[str, str | None]: ...
def compensate_graph(
    augmented: _Path,
    controller: _Path,
    report: _Path | None = None,
    reference: _Path | None = None,
    keep: bool = False,
    measured_alpha: list[str] = ...,
    delay_margin: float | None = None,
) -> tuple[str, str]: ...
def psd_welch(
    x: _F64, fs_hz: float, segment_len: int = 1024, overlap: float = 0.5, window: str = "hann", detrend: str = "mean"
) -> tuple[_F64, _F64]:
    """One-sided Welch PSD (scipy's density conventions): (f_hz, S in unit²/Hz).
    window: "hann" | "hamming" | "rectangular"; detrend: "mean" | "linear" | "none"."""

def cumulative_psd(
    x: _F64,
    fs_hz: float,
    segment_len: int | None = None,
    overlap: float = 0.5,
    window: str = "hann",
    detrend: str = "mean",
) -> tuple[_F64, _F64]:
    """Cumulative PSD (unit²): (f_hz, C); its end value is the mean square of the
    detrended signal. segment_len=None: the segments of nanomotion run's plot."""

def frf_h1(
    u: _F64,
    y: _F64,
    fs_hz: float,
    segment_len: int = 1024,
    overlap: float = 0.5,
    window: str = "hann",
    detrend: str = "mean",
) -> tuple[_F64, _C128, _F64]:
    """Open-loop H1 FRF estimate S_yu/S_uu: (f_hz, H, coherence)."""

class Lti:
    """A linear time-invariant model (continuous when dt is None)."""
    @staticmethod
    def tf(num: list[float], den: list[float], dt: float | None = None) -> Lti:
        """num/den in descending powers of s (z when dt is given)."""
    @staticmethod
    def ss(a: _F64, b: _F64, c: _F64, d: _F64, dt: float | None = None) -> Lti:
        """x' = A x + B u, y = C x + D u (2-D float arrays)."""
    @property
    def dt(self) -> float | None: ...
    @property
    def shape(self) -> tuple[int, int, int]:
        """(outputs, inputs, states)."""
    def freqresp(self, w_rad_s: _F64) -> _C128:
        """Response at w (rad/s): shape (N,) SISO, (N, outputs, inputs) MIMO."""
    def poles(self) -> _C128: ...
    def is_stable(self) -> bool: ...
    def hinfnorm(self) -> tuple[float, float]:
        """(‖G‖∞, peak frequency in rad/s); AnalysisError if unstable."""
    def margins(self) -> dict[str, float]:
        """gain_margin, gain_margin_db, phase_margin_deg, modulus_margin and
        crossover frequencies (rad/s) of this SISO loop gain."""
    def series(self, other: Lti) -> Lti: ...
    def feedback(self, other: Lti, sign: float = -1.0) -> Lti: ...

class ColemanHodgdon:
    """Coleman–Hodgdon hysteresis (6.3): dy/dt = α|du/dt|(b u − y) + c du/dt."""
    def __init__(self, alpha: float, b: float, c: float, retrace: tuple[float, float, float] | None = None) -> None: ...
    def simulate(self, u: _F64, y0: float = 0.0, u0: float = 0.0) -> _F64: ...
    def steady_loop(self, u: _F64, u_min: float, u_max: float, direction: str) -> _F64:
        """The periodic orbit on [u_min, u_max]; direction "trace" or "retrace"."""
    @property
    def params(self) -> tuple[tuple[float, float, float], tuple[float, float, float]]: ...

class HysteresisInverse:
    """Exact inverse feed-forward (6.6) of the extended model (6.4) on [x_lo, x_hi]."""
    def __init__(
        self,
        x_lo: float,
        x_hi: float,
        model: ColemanHodgdon | None = None,
        extended_json: str | None = None,
        standstill: float = 0.0,
    ) -> None: ...
    def voltage(self, x: float, direction: str) -> float: ...
    def position(self, v: float, direction: str) -> float: ...
    def voltage_range(self, direction: str) -> tuple[float, float]: ...
    def run(self, x: _F64) -> _F64: ...
    @property
    def out_of_range(self) -> int: ...

class TimestampEstimator:
    """Time-stamping estimator (8.1)–(8.4) with the Sec. 8.3 fallback."""
    def __init__(
        self,
        resolution: float,
        order: int = 2,
        register_len: int = 5,
        band_counts: float = 1.0,
        fallback: str = "thesis",
        edge_offsets_counts: list[float] = ...,
    ) -> None: ...
    @property
    def register_width(self) -> int: ...
    def estimate(self, t: _F64, registers: _F64) -> tuple[_F64, npt.NDArray[np.uint8]]:
        """Rows [c, n_valid, t_1, x_1, …] (newest first) → ((N, 3) [x, v, a], status)."""

def timestamp_track(
    t: _F64,
    x: _F64,
    v: _F64,
    a: _F64 | None = None,
    encoder_json: str = "{}",
    order: int = 2,
    fallback: str = "thesis",
    seed: int = 0,
) -> tuple[_F64, npt.NDArray[np.uint8], _F64, _F64]: ...

def sweep_plan(path: _Path) -> str: ...
def sweep_pending(path: _Path, out: _Path, restart: bool = False) -> tuple[int, list[int], str]: ...
def sweep_run_chunk(path: _Path, indices: list[int], jobs: int = 1) -> str: ...
def sweep_append(path: _Path, out: _Path, rows_json: str) -> int: ...
def sweep_write(path: _Path, out: _Path) -> dict[str, Any]: ...
class SweepLock:
    @property
    def held(self) -> bool: ...
    def release(self) -> None: ...
    def __enter__(self) -> SweepLock: ...
    def __exit__(self, *exc: object) -> bool: ...
def sweep_lock(out: _Path) -> SweepLock: ...
def sweep_local(
    path: _Path, out: _Path, jobs: int = 0, restart: bool = False, limit: int | None = None
) -> dict[str, Any]: ...
