"""Sweeps: the Rust rayon path and Ray give the same table; a worker killed
mid-study only costs its chunk, which Ray re-runs."""

import csv
import os
from pathlib import Path

import pytest

import nanomotion as nm

STUDY = """\
title: quickstart PI loop, plant variations (test)
graph: {graph}
study: monte-carlo
runs: 12
seed: 2009
set:
  duration_s: 0.55
parameters:
  - path: blocks.stage.den.0
    normal: {{ mean: 0.255, std: 0.01275 }}
  - path: blocks.pi.kp
    values: [2.0e7, 3.1416e7]
"""


@pytest.fixture()
def study(root, tmp_path) -> Path:
    p = tmp_path / "study.yaml"
    text = STUDY.format(graph=root / "examples/quickstart.yaml")
    # `values:` is not a Monte-Carlo distribution: vary kp uniformly instead.
    text = text.replace("values: [2.0e7, 3.1416e7]", "uniform: [2.0e7, 4.0e7]")
    p.write_text(text)
    return p


def table(out: Path) -> list[dict[str, str]]:
    with open(out / "results.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    for r in rows:
        r.pop("wall_s")  # the only column that may differ between engines
    return rows


@pytest.fixture(scope="module")
def ray_local():
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
    yield ray
    ray.shutdown()


def test_local_engine_writes_the_cli_table_and_resumes(study, tmp_path, root, cli):
    from conftest import run_cli

    out = tmp_path / "local"
    s = nm.sweep(study, engine="local", out=out, jobs=2)
    assert (s.planned, s.computed, s.failed) == (12, 12, 0)
    for f in ("results.csv", "results.parquet", "plan.json", "rows.jsonl"):
        assert (out / f).stat().st_size > 0
    rows = table(out)
    assert [int(r["index"]) for r in rows] == list(range(12))
    assert all(float(r["true_err.y.rms"]) > 0 for r in rows)
    again = nm.sweep(study, engine="local", out=out)
    assert (again.resumed, again.computed) == (12, 0)
    # The CLI on the same study writes the same table.
    cli_out = tmp_path / "cli"
    p = run_cli(cli, "sweep", str(study), "--out", str(cli_out), "--jobs", "1")
    assert p.returncode == 0, p.stderr
    assert table(cli_out) == rows


def test_ray_engine_survives_a_killed_worker_and_matches_the_local_table(study, tmp_path, ray_local):
    local = tmp_path / "local"
    nm.sweep(study, engine="local", out=local, jobs=2)

    markers = tmp_path / "markers"
    markers.mkdir()

    def flaky(study_path, indices):
        # The first attempt of the chunk holding run 0 kills its worker process.
        import nanomotion

        m = markers / f"chunk{indices[0]}"
        if indices[0] == 0 and not m.exists():
            m.write_text(str(os.getpid()))
            os._exit(1)
        return nanomotion.run_chunk(study_path, indices)

    out = tmp_path / "ray"
    s = nm.sweep(study, engine="ray", out=out, chunk_size=3, max_retries=2, task=flaky)
    assert (markers / "chunk0").exists()  # the worker really died once
    assert (s.planned, s.computed, s.failed, s.resumed) == (12, 12, 0, 0)
    assert table(out) == table(local)
    # Everything is in the store: a second call computes nothing.
    again = nm.sweep(study, engine="ray", out=out)
    assert (again.resumed, again.computed) == (12, 0)
    assert table(out) == table(local)


def test_bad_study_and_engine_raise_sweep_errors(tmp_path, study):
    bad = tmp_path / "bad.yaml"
    bad.write_text("graph: nowhere.yaml\nstudy: grid\nparameters: []\n")
    with pytest.raises(nm.SweepError):
        nm.sweep(bad, out=tmp_path / "o")
    with pytest.raises(nm.SweepError, match="engine `dask`"):
        nm.sweep(study, engine="dask", out=tmp_path / "o")


def test_a_locked_output_folder_is_refused_until_released(study, tmp_path):
    # The Ray engine holds the folder's lock for the whole study (as the CLI
    # does): while a lock is held, another sweep into the folder is refused
    # with the lock named; after release it runs.
    from nanomotion import _nanomotion as _nm

    out = tmp_path / "locked"
    with _nm.sweep_lock(str(out)) as lock:
        assert lock.held
        assert (out / ".nanomotion.lock").exists()
        with pytest.raises(nm.SweepError, match="being written by another nanomotion process"):
            nm.sweep(study, engine="local", out=out, jobs=1, limit=1)
    assert not lock.held
    assert not (out / ".nanomotion.lock").exists()
    s = nm.sweep(study, engine="local", out=out, jobs=1, limit=1)
    assert s.computed == 1
