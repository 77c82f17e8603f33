#!/usr/bin/env python3
"""The criterion benches of two or more builds, alternated run by run.

Each round runs every build's `trace` bench binary once (the order alternating between rounds),
builds single-threaded (`RAYON_NUM_THREADS=1`: two-thread builds vary by ±10% run to run) and
the ray benches as they run by default, each run with its own `CRITERION_HOME` so that no run
compares itself with another. Per bench it reports every build's median time against the
first's, per round, as the median with the range of the speed ratio (first ms ÷ build ms).
Usage:

    cargo bench --bench trace --no-run
    RUSTFLAGS="-C debuginfo=0" cargo bench --bench trace --no-run --target-dir target/portable
    python3 compare/criterion_builds.py --rounds 2 --out compare/results/isa/criterion.json \\
        native=target/release/deps/trace-HASH dependency=target/portable/release/deps/trace-HASH

A build may carry environment settings after its path, separated by commas
(`avx512=target/release/deps/trace-HASH,STRAHL_ISA=avx512`).
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from builds import parse_build  # noqa: E402  (the same LABEL=PATH[,KEY=VALUE...] syntax)


def medians(home):
    """Bench id → median time in ms, from a criterion output tree."""
    out = {}
    for root, _, files in os.walk(home):
        if os.path.basename(root) == "new" and "estimates.json" in files and "benchmark.json" in files:
            with open(os.path.join(root, "benchmark.json")) as f:
                name = json.load(f)["full_id"]
            with open(os.path.join(root, "estimates.json")) as f:
                out[name] = json.load(f)["median"]["point_estimate"] / 1e6
    return out


def run(build, args, home):
    label, path, env = build
    groups = {"build": ("^build/", {"RAYON_NUM_THREADS": "1"}), "rays": ("^rays/", {})}
    for flt, threads in (groups[g] for g in (["build", "rays"] if args.only == "all" else [args.only])):
        cmd = [path, "--bench", "--warm-up-time", str(args.warm_up), "--measurement-time", str(args.measurement),
               flt + (args.filter or "")]
        res = subprocess.run(cmd, env={**os.environ, **env, **threads, "CRITERION_HOME": home},
                             capture_output=True, text=True)
        if res.returncode != 0:
            sys.exit(f"{label}: {' '.join(cmd)} failed:\n{res.stderr[-2000:]}")
    times = medians(home)
    if not times:
        sys.exit(f"{label}: no bench ran (filter {args.filter!r})")
    return times


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--warm-up", type=float, default=1.0, help="criterion warm-up seconds")
    p.add_argument("--measurement", type=float, default=3.0, help="criterion measurement seconds")
    p.add_argument("--filter", default="", help="a regex appended after ^build/ and ^rays/")
    p.add_argument("--only", default="all", choices=["all", "build", "rays"],
                   help="which bench groups to run")
    p.add_argument("--out", help="JSON report")
    p.add_argument("builds", nargs="+", type=parse_build)
    args = p.parse_args()
    if len(args.builds) < 2:
        sys.exit("need at least two builds")
    per = {b[0]: [] for b in args.builds}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.rounds):
            order = args.builds if r % 2 == 0 else list(reversed(args.builds))
            for b in order:
                per[b[0]].append(run(b, args, os.path.join(tmp, f"{b[0]}_{r}")))
            print(f"round {r + 1}/{args.rounds} done", file=sys.stderr, flush=True)
    first = args.builds[0][0]
    names = sorted(set.intersection(*(set(t) for runs in per.values() for t in runs)))
    report = {"rounds": args.rounds, "builds": {b[0]: {"path": b[1], "env": b[2]} for b in args.builds}, "benches": {}}
    lines = [f"| bench | {first} ms | " + " | ".join(f"{b[0]} ms | {b[0]} speed ÷ {first}, median [range]"
                                                     for b in args.builds[1:]) + " |",
             "|---|---:|" + "---:|---|" * (len(args.builds) - 1)]
    for n in names:
        base = [t[n] for t in per[first]]
        entry = {first: base}
        row = [n, f"{statistics.median(base):.3f}"]
        for b in args.builds[1:]:
            mine = [t[n] for t in per[b[0]]]
            ratio = [x / y for x, y in zip(base, mine)]
            entry[b[0]] = mine
            entry[f"{b[0]}_speed_ratio"] = ratio
            row += [f"{statistics.median(mine):.3f}",
                    f"{statistics.median(ratio):.3f} [{min(ratio):.3f}–{max(ratio):.3f}]"]
        report["benches"][n] = entry
        lines.append("| " + " | ".join(row) + " |")
    print("\n".join(lines))
    if args.out:
        with open(args.out, "w") as f:
            json.dump(report, f, indent=1)


if __name__ == "__main__":
    main()
