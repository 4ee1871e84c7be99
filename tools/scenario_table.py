#!/usr/bin/env python3
"""Summarise the first N records of a `scenarios` run from its per-record lines.

    cargo run --release -p nanomotion-plf --example scenarios -- 300 2> run.log
    python3 tools/scenario_table.py run.log [N] [--csv OLD.csv] [--visibility VIS.csv]

The per-record lines (stderr) are what `scenarios` prints as it goes, so a run
cut short still gives the table of its first N records — the same records, in
the same order, as `scenarios -- N` (held-out seeds are drawn in seed order).
The measures are the example's own: named correctly, padding, false alarms,
precision/recall per effect, per-family rates. With `--csv OLD.csv` (a
previous run's `--csv` output) the same first N seeds of that run are
summarised beside it. With `--visibility VIS.csv` (the output of `scenarios
-- N --visibility-only`: what each record's hidden effects change over its
noise) recall and the rate named correctly are also given on the records
whose effects stand out of the noise (visibility ≥ 1), and on the others;
then the same split by the visibility in the held-out part alone (the only
part that decides a name) and by what is left there once the nominal
calibration has taken what it can (`calibrated_visibility`: an effect below 1
there cannot be told from a nominal that is off), for the columns VIS.csv has.
With the column `calibrated_per_effect` (each hidden effect's own calibrated
visibility, the others kept), the issue's "where the effect allows it": a
record is named correctly when every effect it allows (own visibility ≥ 1) is
named and nothing that is not hidden is; recall per effect over the records
that allow it.
"""
import collections
import csv
import re
import sys

LINE = re.compile(
    r"^\[(\d+)/\d+\] seed (\d+): Family \{ plant: \"(\w+)\", loop_kind: \"(\w+)\", "
    r"excitation: \"(\w+)\", noise: \"(\w+)\", nominal: \"(\w+)\", rate_hz: ([\d.]+), "
    r"unit: \"(\w+)\" \} hidden \[(.*?)\] found \[(.*?)\] cut (-?[\d.]+|NaN) %"
)


def names(s):
    return [x.strip().strip('"') for x in s.split(",") if x.strip()]


def from_log(path):
    rows = []
    for line in open(path, encoding="utf-8"):
        m = LINE.match(line)
        if m:
            g = m.groups()
            rows.append(dict(seed=int(g[1]), plant=g[2], loop=g[3], excitation=g[4],
                             noise=g[5], nominal=g[6], hidden=names(g[9]),
                             found=names(g[10]), cut=float(g[11])))
    return rows


def from_csv(path):
    rows = []
    for r in csv.DictReader(open(path, encoding="utf-8")):
        rows.append(dict(seed=int(r["seed"]), plant=r["plant"], loop=r["loop"],
                         excitation=r["excitation"], noise=r["noise"],
                         nominal=r["nominal"],
                         hidden=[] if r["hidden"] == "none" else r["hidden"].split("+"),
                         found=[x for x in r["found"].split("+") if x],
                         cut=float(r["holdout_cut_percent"])))
    return rows


def summary(rows):
    pct = lambda a, b: "—" if b == 0 else f"{100 * a / b:.0f} %"
    n = len(rows)
    ok = lambda r: len(r["found"]) == len(r["hidden"]) and all(h in r["found"] for h in r["hidden"])
    correct = sum(ok(r) for r in rows)
    correct_cut = sum(ok(r) and (not r["hidden"] or r["cut"] >= 50) for r in rows)
    eff = [r for r in rows if r["hidden"]]
    clean = [r for r in rows if not r["hidden"]]
    padded = sum(any(f not in r["hidden"] for f in r["found"]) for r in eff)
    alarms = sum(bool(r["found"]) for r in clean)
    out = {
        "named correctly": f"{pct(correct, n)} ({correct} of {n})",
        "named correctly, held-out cut ≥ 50 %": f"{pct(correct_cut, n)} ({correct_cut} of {n})",
        "padding": f"{pct(padded, len(eff))} ({padded} of {len(eff)})",
        "false alarms": f"{pct(alarms, len(clean))} ({alarms} of {len(clean)})",
    }
    per = collections.defaultdict(lambda: [0, 0, 0])
    for r in rows:
        for h in r["hidden"]:
            per[h][0] += 1
            per[h][2] += h in r["found"]
        for f in r["found"]:
            per[f][1] += 1
    for e in sorted(per):
        h, nm, both = per[e]
        out[f"{e} precision / recall"] = f"{pct(both, nm)} / {pct(both, h)}"
    for dim in ["nominal", "plant", "loop"]:
        for v in sorted({r[dim] for r in rows}):
            sub = [r for r in rows if r[dim] == v]
            out[f"{dim} {v}"] = f"{pct(sum(ok(r) for r in sub), len(sub))} of {len(sub)}"
    return out


def visible_split(rows, vis, label):
    """Named correctly and per-effect recall on records with effects above the
    noise (visibility ≥ 1, by `label`) and below it."""
    pct = lambda a, b: "—" if b == 0 else f"{100 * a / b:.0f} %"
    ok = lambda r: len(r["found"]) == len(r["hidden"]) and all(h in r["found"] for h in r["hidden"])
    eff = [r for r in rows if r["hidden"]]
    above = [r for r in eff if vis[r["seed"]] >= 1.0]
    below = [r for r in eff if vis[r["seed"]] < 1.0]
    print(f"\nrecords with an effect: {len(above)} with {label} ≥ 1, {len(below)} below\n")
    print(f"| measure | {label} ≥ 1 | below 1 |\n|---|---|---|")
    print(f"| named correctly | {pct(sum(map(ok, above)), len(above))} ({sum(map(ok, above))} of {len(above)}) "
          f"| {pct(sum(map(ok, below)), len(below))} ({sum(map(ok, below))} of {len(below)}) |")
    effects = sorted({h for r in eff for h in r["hidden"]})
    for e in effects:
        cells = []
        for group in (above, below):
            hid = [r for r in group if e in r["hidden"]]
            got = sum(e in r["found"] for r in hid)
            cells.append(f"{pct(got, len(hid))} ({got} of {len(hid)})")
        print(f"| {e} recall | {cells[0]} | {cells[1]} |")


def allowed_split(rows, per_effect):
    """Named correctly where the effects allow it: every hidden effect whose own
    calibrated visibility is ≥ 1 named, nothing named that is not hidden;
    recall per effect over the records that allow it."""
    pct = lambda a, b: "—" if b == 0 else f"{100 * a / b:.0f} %"
    eff = [r for r in rows if r["hidden"]]
    allows = [r for r in eff if any(per_effect[r["seed"]].get(h, 0.0) >= 1.0 for h in r["hidden"])]
    none = [r for r in eff if r not in allows]

    def ok(r):
        allowed = {h for h in r["hidden"] if per_effect[r["seed"]].get(h, 0.0) >= 1.0}
        return allowed <= set(r["found"]) <= set(r["hidden"])

    print(f"\nwhere the effect allows it (each hidden effect's own calibrated visibility ≥ 1): "
          f"{len(allows)} records allow at least one, {len(none)} none\n")
    print("| measure | records allowing an effect | records allowing none |\n|---|---|---|")
    print(f"| every allowed effect named, nothing unhidden | {pct(sum(map(ok, allows)), len(allows))} "
          f"({sum(map(ok, allows))} of {len(allows)}) | {pct(sum(map(ok, none)), len(none))} "
          f"({sum(map(ok, none))} of {len(none)}) |")
    effects = sorted({h for r in eff for h in r["hidden"]})
    for e in effects:
        hid = [r for r in eff if e in r["hidden"] and per_effect[r["seed"]].get(e, 0.0) >= 1.0]
        got = sum(e in r["found"] for r in hid)
        hidden_not = sum(e in r["hidden"] for r in eff) - len(hid)
        print(f"| {e} recall where allowed | {pct(got, len(hid))} ({got} of {len(hid)}; {hidden_not} not allowed) | |")


def main():
    args = sys.argv[1:]
    old = None
    vis_path = None
    if "--visibility" in args:
        i = args.index("--visibility")
        vis_path = args[i + 1]
        del args[i:i + 2]
    if "--csv" in args:
        i = args.index("--csv")
        old = args[i + 1]
        del args[i:i + 2]
    rows = from_log(args[0])
    n = int(args[1]) if len(args) > 1 else len(rows)
    rows = rows[:n]
    new = summary(rows)
    cols = [new]
    if old:
        seeds = [r["seed"] for r in rows]
        by_seed = {r["seed"]: r for r in from_csv(old)}
        missing = [s for s in seeds if s not in by_seed]
        if missing:
            sys.exit(f"{old} lacks seeds {missing[:5]}…: give the CSV of a run over the same records")
        cols.append(summary([by_seed[s] for s in seeds]))
    print(f"first {len(rows)} records (seeds {rows[0]['seed']}–{rows[-1]['seed']})\n")
    print("| measure | this run |" + (" previous run |" if old else ""))
    print("|---|---|" + ("---|" if old else ""))
    for k in new:
        print(f"| {k} | " + " | ".join(c.get(k, "—") for c in cols) + " |")
    if vis_path:
        table = list(csv.DictReader(open(vis_path)))
        for column in ("visibility", "held_out_visibility", "calibrated_visibility"):
            if not table or column not in table[0]:
                continue
            vis = {int(r["seed"]): float(r[column]) for r in table}
            missing = [r["seed"] for r in rows if r["seed"] not in vis]
            if missing:
                sys.exit(f"{vis_path} lacks seeds {missing[:5]}…: run --visibility-only over the same records")
            visible_split(rows, vis, column.replace("_", " "))
        if table and "calibrated_per_effect" in table[0]:
            per_effect = {
                int(r["seed"]): {
                    e: float(x) for e, x in (kv.split(":") for kv in r["calibrated_per_effect"].split())
                }
                for r in table
            }
            allowed_split(rows, per_effect)


if __name__ == "__main__":
    main()
