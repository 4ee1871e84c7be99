#!/usr/bin/env python3
"""Wake-up latency of `nanomotion rt` (the quickstart loop) next to cyclictest.

For each rate, runs the quickstart single-rate at that rate on the wall clock
(SCHED_FIFO, memory locked, /dev/cpu_dma_latency held at 0 as cyclictest holds
it, same priority and CPU as cyclictest), then
cyclictest (Debian `rt-tests`) at the same period and priority, in the same
minutes, and prints one Markdown table row per tool and rate: wake-up latency
p50/p99/p99.9/max (µs), period jitter (max |period − T|, µs) and overruns.

    cargo build --release
    python3 tools/rt_latency_table.py --cycles 100000 [--rates 1000,4000,10000,20000] [--cpu 1]

Needs root (or CAP_SYS_NICE and a memlock limit) and `cyclictest` on PATH
(`apt-get install -y rt-tests`). cyclictest reports whole µs; its p99/p99.9 come
from its histogram (`-h`), its max from its own summary.
"""

import argparse
import json
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BIN = os.path.join(ROOT, "target", "release", "nanomotion")
GRAPH = os.path.join(ROOT, "examples", "quickstart.yaml")


def quantile_from_hist(counts, total, q):
    """Smallest bucket (µs) whose cumulative count reaches ceil(q * total)."""
    rank = min(total, max(1, math.ceil(q * total)))
    seen = 0
    for us, c in sorted(counts.items()):
        seen += c
        if seen >= rank:
            return us
    return None


def nanomotion(rate, cycles, prio, cpu):
    out = tempfile.mkdtemp(prefix="nm-rt-")
    sets = [f"base_rate_hz={rate}"] + [
        f"blocks.{b}.rate_hz={rate}" for b in ("ref", "err", "pi", "encoder")
    ]
    cmd = [BIN, "rt", GRAPH, "--duration", str(cycles / rate), "--priority", str(prio),
           "--out", out, "--force"]
    if cpu is not None:
        cmd += ["--cpu", str(cpu)]
    for s in sets:
        cmd += ["--set", s]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    with open(os.path.join(out, "timing.json")) as f:
        t = json.load(f)
    shutil.rmtree(out)
    us = lambda ns: ns / 1000.0
    if not t.get("cpu_latency_held"):
        print(f"note: {rate} Hz run without the CPUs held out of deep idle states: "
              f"{t.get('cpu_latency_refused')}", file=sys.stderr)
    lat = t["wakeup_latency"]
    jitter = t["period_jitter"]["max_ns"]
    return dict(
        p50=us(lat["p50_ns"]), p99=us(lat["p99_ns"]), p999=us(lat["p999_ns"]),
        max=us(lat["max_ns"]), jitter=us(jitter), overruns=t["overruns"],
        cycles=t["ticks"], sched=t["scheduling"], cmd=" ".join(cmd[1:]),
    )


def cyclictest(rate, cycles, prio, cpu):
    interval = round(1e6 / rate)
    cmd = ["cyclictest", "-m", "-q", "-t1", "-p", str(prio), "-i", str(interval),
           "-l", str(cycles), "-h", "2000"]
    if cpu is not None:
        cmd += ["-a", str(cpu)]
    r = subprocess.run(cmd, check=True, capture_output=True, text=True)
    counts = {}
    for line in r.stdout.splitlines():
        m = re.match(r"^(\d+)\s+(\d+)$", line.strip())
        if m:
            counts[int(m.group(1))] = int(m.group(2))
    mx = re.search(r"# Max Latencies:\s+(\d+)", r.stdout)
    ov = re.search(r"# Histogram Overflows:\s+(\d+)", r.stdout)
    # Cycles above the histogram's 2000 µs are counted as overflows: they are
    # the largest values, so they count in the total but in no bucket below.
    total = sum(counts.values()) + (int(ov.group(1)) if ov else 0)
    return dict(
        p50=quantile_from_hist(counts, total, 0.5),
        p99=quantile_from_hist(counts, total, 0.99),
        p999=quantile_from_hist(counts, total, 0.999),
        max=int(mx.group(1)) if mx else None,
        overflows=int(ov.group(1)) if ov else None,
        cycles=total, cmd=" ".join(cmd),
    )


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cycles", type=int, default=100_000)
    ap.add_argument("--rates", default="1000,4000,10000,20000")
    ap.add_argument("--priority", type=int, default=80)
    ap.add_argument("--cpu", type=int, default=None)
    a = ap.parse_args()
    if not os.path.exists(BIN):
        sys.exit(f"{BIN} not found (fix: cargo build --release)")
    print("| rate | tool | cycles | p50 µs | p99 µs | p99.9 µs | max µs | max |period − T| µs | overruns |")
    print("|---|---|---|---|---|---|---|---|---|")
    for rate in [int(r) for r in a.rates.split(",")]:
        n = nanomotion(rate, a.cycles, a.priority, a.cpu)
        c = cyclictest(rate, a.cycles, a.priority, a.cpu)
        print(f"| {rate / 1000:g} kHz | nanomotion rt | {n['cycles']} | {n['p50']:.1f} | {n['p99']:.1f} "
              f"| {n['p999']:.1f} | {n['max']:.1f} | {n['jitter']:.1f} | {n['overruns']} |")
        q = lambda v: "> 2000" if v is None else v  # beyond cyclictest's histogram
        print(f"| | cyclictest | {c['cycles']} | {q(c['p50'])} | {q(c['p99'])} | {q(c['p999'])} | {c['max']} | – | – |")
        sys.stdout.flush()


if __name__ == "__main__":
    main()
