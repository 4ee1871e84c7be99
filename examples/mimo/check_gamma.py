"""Independent check of γ: python-control's hinfsyn (SLICOT SB10AD, γ-iteration)
on the generalised plant that `nanomotion synth` wrote.

    pip install slycot control
    python3 examples/mimo/check_gamma.py out/mimo/generalized_plant.json

Prints SLICOT's γ and, if report.json sits beside the plant, ours and the
relative difference. Not part of CI (python-control/slycot are not installed
there); the result of our run is recorded in docs/mimo.md.
"""
import json
import os
import sys

import numpy as np
import control as ct

path = sys.argv[1]
p = json.load(open(path))
P = ct.ss(np.array(p["a"]), np.array(p["b"]), np.array(p["c"]), np.array(p["d"]))
try:
    K, CL, gamma, rcond = ct.hinfsyn(P, p["nmeas"], p["ncon"])
except Exception as e:  # SLICOT refuses near-axis weights (rank test at ω ≈ 0)
    print(f"SLICOT failed: {type(e).__name__}: {str(e).strip().splitlines()[0] if str(e).strip() else ''}")
    sys.exit(1)
norm = max(np.linalg.svd(CL(1j * w), compute_uv=False)[0] for w in np.logspace(-8, 6, 4000))
print(f"SLICOT gamma = {gamma:.6f}, controller order {K.nstates}, grid sup sigma(N) = {norm:.6f}")
rep = os.path.join(os.path.dirname(path), "report.json")
if os.path.exists(rep):
    ours = json.load(open(rep))["gamma"]
    print(f"nanomotion gamma = {ours:.6f}, relative difference {(ours - gamma) / gamma:+.3%}")
