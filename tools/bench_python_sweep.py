#!/usr/bin/env python3
"""Runs per second of the 1 000-run Monte-Carlo of the quickstart
(examples/sweep/quickstart_monte_carlo.yaml): nanomotion's local engine on 1 and
2 threads, nanomotion on a local Ray instance (2 CPUs), and the same study
written with python-control (``forced_response`` per run).

    python3 tools/bench_python_sweep.py [--runs N] [--skip-ray] [--skip-control]

Needs the nanomotion wheel installed (see docs/python.md), and ``ray`` and
``control`` (python-control) for those rows. Prints a markdown table.

The python-control model is the honest linear equivalent of the quickstart loop
at one rate: the stage P(s) = (c·b s + c·k) / (M s³ + b s² + k s) discretised by
ZOH at the 4 kHz control rate, the PI kp (s + 2π·4 Hz)/s by Tustin, unity
feedback, the 10 µm/s ramp as reference, error rms from 0.5 s. It omits what the
nanomotion graph has and a linear model cannot: the 5 nm encoder quantiser, the
±2000 Hz drive-frequency limits with anti-windup, and the 40 kHz plant rate with
its rate transitions. Each run uses the same (M, c·k) draw as the nanomotion run
with the same index (read from the study's plan).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

import nanomotion as nm

ROOT = Path(__file__).resolve().parents[1]
STUDY = ROOT / "examples/sweep/quickstart_monte_carlo.yaml"


def study_with_runs(runs: int, tmp: Path) -> Path:
    text = STUDY.read_text().replace("graph: ../quickstart.yaml", f"graph: {ROOT / 'examples/quickstart.yaml'}")
    text = text.replace("runs: 1000", f"runs: {runs}")
    p = tmp / "study.yaml"
    p.write_text(text)
    return p


def nanomotion_rate(study: Path, tmp: Path, engine: str, jobs: int = 0) -> tuple[float, int, Path]:
    out = tmp / f"out_{engine}_{jobs}"
    shutil.rmtree(out, ignore_errors=True)
    t0 = time.perf_counter()
    s = nm.sweep(study, engine=engine, out=out, jobs=jobs)
    wall = time.perf_counter() - t0  # includes planning and writing the table
    return s.computed / wall, s.failed, out


def control_rate(study: Path, runs: int) -> tuple[float, np.ndarray]:
    import control as ct

    plan = json.loads(nm._nanomotion.sweep_plan(str(study)))
    fs, dur, kp, zero_hz = 4000.0, 2.0, 3.1416e7, 4.0
    t = np.arange(int(dur * fs)) / fs
    r = 1e-5 * t
    c_pi = ct.sample_system(ct.tf([kp, kp * 2 * np.pi * zero_hz], [1.0, 0.0]), 1 / fs, method="tustin")
    first = int(0.5 * fs)
    rms = np.empty(runs)
    t0 = time.perf_counter()
    for k, run in enumerate(plan["runs"][:runs]):
        p = {o["path"]: o["value"] for o in run["parameters"]}
        m, ck = p["blocks.stage.den.0"], p["blocks.stage.num.1"]
        stage = ct.tf([3.685e-4, ck], [m, 92.1, 3.32837e6, 0.0])
        loop = c_pi * ct.sample_system(stage, 1 / fs, method="zoh")
        sens = ct.feedback(1, loop)  # r -> e
        e = ct.forced_response(sens, T=t, U=r).outputs
        rms[k] = np.sqrt(np.mean(e[first:] ** 2))
    wall = time.perf_counter() - t0
    return runs / wall, rms


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=1000)
    ap.add_argument("--skip-ray", action="store_true")
    ap.add_argument("--skip-control", action="store_true")
    a = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="nm_bench_"))
    study = study_with_runs(a.runs, tmp)
    rows = []
    for jobs in (1, 2):
        rate, failed, out = nanomotion_rate(study, tmp, "local", jobs)
        rows.append((f"nanomotion, engine=\"local\", {jobs} thread(s)", rate, failed))
    local_out = out
    if not a.skip_ray:
        import ray

        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
        t0 = time.perf_counter()
        ray.get(ray.remote(lambda: None).remote())  # workers up before timing
        startup = time.perf_counter() - t0
        rate, failed, out = nanomotion_rate(study, tmp, "ray")
        rows.append(("nanomotion, engine=\"ray\", local ray.init(num_cpus=2)", rate, failed))
        ray.shutdown()
        print(f"(Ray worker start-up before timing: {startup:.1f} s)")
    ctl_rms = None
    if not a.skip_control:
        rate, ctl_rms = control_rate(study, a.runs)
        rows.append(("python-control 0.10 `forced_response`, 1 process (linear 4 kHz equivalent)", rate, 0))
    print(f"\n{a.runs}-run Monte-Carlo of the quickstart (2 s simulated per run), os.cpu_count() = {os.cpu_count()}\n")
    print("| engine | runs/s | failed runs |")
    print("|---|---|---|")
    for name, rate, failed in rows:
        print(f"| {name} | {rate:.1f} | {failed} |")
    if ctl_rms is not None:
        res = nm.read_results(local_out)
        mine = np.array([float(r["true_err.y.rms"]) for r in res])
        ratio = ctl_rms / mine
        print(f"\nerror rms, python-control linear model / nanomotion true_err.y: median {np.median(ratio):.3f}, "
              f"5-95 % [{np.percentile(ratio, 5):.3f}, {np.percentile(ratio, 95):.3f}] "
              f"(nanomotion medians: {np.median(mine):.3e} m; linear model: {np.median(ctl_rms):.3e} m)")
    shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
