#!/usr/bin/env python3
"""Run a command with /dev/cpu_dma_latency held at 0 µs (what cyclictest does by
default): the CPUs stay out of deep idle states while the command runs.

    sudo python3 tools/hold_dma_latency.py target/release/nanomotion rt examples/quickstart.yaml --duration 25 --out /tmp/rt-held --force

docs/performance.md ("Real-time loop") compares `rt` with and without it.
"""

import os
import struct
import subprocess
import sys

if len(sys.argv) < 2:
    sys.exit("usage: hold_dma_latency.py COMMAND [ARGS...]")
try:
    fd = os.open("/dev/cpu_dma_latency", os.O_WRONLY)
except OSError as e:
    sys.exit(f"/dev/cpu_dma_latency: {e} (fix: run as root)")
os.write(fd, struct.pack("i", 0))
try:
    sys.exit(subprocess.run(sys.argv[1:]).returncode)
finally:
    os.close(fd)
