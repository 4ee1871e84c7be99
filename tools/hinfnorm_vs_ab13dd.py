#!/usr/bin/env python3
"""Our `hinfnorm` against SLICOT's `ab13dd` on the same systems (issue 29).

A measurement tool, not a CI step. The systems are the `lti_numerics` bench's
`hinf_ratio` ones (random stable 2 x 2 models at n = 10, 20, 40, 80, continuous
`c` and discrete `d`, seeded), written as JSON by the Rust example
`hinf_systems` together with our norm and time per call (median of 7 batches,
release build); this script times `slycot.ab13dd` on the same matrices in the
same way. Rounds alternate the two (Rust process, then ab13dd) and each figure
is the median over the rounds, so the ratio comes from one run on a noisy
machine. It fails if a norm differs from ab13dd's by more than 1e-12 relative.

Install slycot (needs a Fortran compiler and LAPACK when no wheel fits), e.g.
in a venv of its own so that python-control elsewhere does not pick it up:

    apt-get install -y gfortran liblapack-dev libblas-dev cmake
    python3 -m venv /work/venv-slycot
    /work/venv-slycot/bin/pip install numpy slycot

Run from the repository root:

    /work/venv-slycot/bin/python tools/hinfnorm_vs_ab13dd.py [--rounds 3] [--seconds 0.5]

ab13dd is timed with its default `tol` = 1e-10 (ours is fixed at about
1e-10 too, then polished by a golden-section search); the norms are compared
with ab13dd called again with `tol` = 1e-13 (`rel. diff`), so that the
comparison is not limited by ab13dd's stopping rule.
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

# One thread, as our Rust code (and before numpy loads OpenBLAS): its threads
# would only compete with each other on a loaded 2-core machine.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import slycot  # noqa: E402


def seconds_per_call(budget, f):
    """Median over 7 batches of the seconds per call of f (as the Rust side)."""
    t = time.perf_counter()
    f()
    once = max(time.perf_counter() - t, 1e-7)
    reps = max(int(budget / 7.0 / once), 1)
    batches = []
    for _ in range(7):
        t = time.perf_counter()
        for _ in range(reps):
            f()
        batches.append((time.perf_counter() - t) / reps)
    return sorted(batches)[3]


def ab13dd(s, tol=1e-10):
    """A call of slycot.ab13dd on the system s (ab13dd's default tol)."""
    a, b, c, d = (np.array(s[k], dtype=float, order="F") for k in "abcd")
    n, m, p = s["n"], b.shape[1], c.shape[0]
    dico = "C" if s["dt"] is None else "D"
    e = np.eye(n, order="F")
    return lambda: slycot.ab13dd(dico, "I", "S", "D", n, m, p, a, e, b, c, d, tol)


def ours(budget):
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "hinf_systems.json")
        subprocess.run(
            [
                "cargo", "run", "--quiet", "--release", "-p", "nanomotion-core",
                "--example", "hinf_systems", "--", path, str(budget),
            ],
            check=True,
        )
        with open(path) as f:
            return json.load(f)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--seconds", type=float, default=0.5,
                    help="timing budget per system and solver")
    args = ap.parse_args()
    times = {}
    systems = None
    for _ in range(args.rounds):
        systems = ours(args.seconds)
        for s in systems:
            rec = times.setdefault(s["name"], {"ours": [], "before": [], "ab13dd": []})
            rec["ours"].append(s["seconds"])
            rec["before"].append(s["before_seconds"])
            rec["ab13dd"].append(seconds_per_call(args.seconds, ab13dd(s)))
    print(f"# {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, "
          f"load {os.getloadavg()[0]:.1f}, {args.rounds} rounds, slycot {slycot.__version__}")
    print("| system | ‖G‖∞ ours | ab13dd | rel. diff | ours | ab13dd | ours/ab13dd "
          "| pre-#29 | pre-#29/ab13dd |")
    print("|---|---|---|---|---|---|---|---|---|")
    worst = 0.0
    for s in systems:
        gpeak, _ = ab13dd(s, tol=1e-13)()
        rel = abs(s["norm"] - gpeak) / gpeak
        worst = max(worst, rel)
        t = {k: statistics.median(v) for k, v in times[s["name"]].items()}
        print(f"| {s['name']} | {s['norm']:.15g} | {gpeak:.15g} | {rel:.1e} "
              f"| {t['ours'] * 1e3:.3f} ms | {t['ab13dd'] * 1e3:.3f} ms "
              f"| {t['ours'] / t['ab13dd']:.2f} | {t['before'] * 1e3:.3f} ms "
              f"| {t['before'] / t['ab13dd']:.2f} |")
    if worst > 1e-12:
        sys.exit(f"norms disagree with ab13dd: worst relative difference {worst:.1e}")


if __name__ == "__main__":
    main()
