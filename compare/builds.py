#!/usr/bin/env python3
"""Two or more builds of `compare` on the same rays, interleaved run by run.

Two binaries cannot interleave passes inside one process, so this runs each build for one timed
run of a few timed passes (after the harness's warm-up pass; the fastest pass counts) in turn, round after round, the order alternating
between rounds so that neither build always runs first. Every run traces the same rays (the
harness seeds its ray generator) with strahl and with Embree, the same system library for every
build. Per scene and class it reports, for each build against the first:

- the ratio of strahl's best kernel-mode Mrays/s (the fastest pass of the fastest API), per round;
- the same ratio divided by the ratio of Embree's best Mrays/s in the two runs (strahl against
  the machine's drift between two runs seconds apart);

each as the median over the rounds with the range. Usage:

    python3 compare/builds.py --rounds 10 --out compare/results/isa/builds.json \\
        native=target/release/compare dependency=target/portable/release/compare \\
        -- ../shared/scenes/teapot ../shared/scenes/sponza_dabrovic

A build may carry environment settings after its path, separated by commas:
`avx2=target/release/compare,STRAHL_ISA=avx2`.
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile


def parse_build(text):
    label, _, rest = text.partition("=")
    if not label or not rest:
        raise argparse.ArgumentTypeError(f"{text}: expected LABEL=PATH[,KEY=VALUE...]")
    path, *settings = rest.split(",")
    env = {}
    for s in settings:
        k, sep, v = s.partition("=")
        if not sep:
            raise argparse.ArgumentTypeError(f"{s}: expected KEY=VALUE")
        env[k] = v
    return label, path, env


def best(mrays):
    return max(mrays.values())


def run(build, scenes, args, tmp, k):
    label, path, env = build
    out = os.path.join(tmp, f"{label}_{k}")
    cmd = [path, *scenes, "--passes", str(args.passes), "--width", str(args.width), "--threads", str(args.threads),
           "--out", out, "--json", out + ".json"]
    res = subprocess.run(cmd, env={**os.environ, **env}, capture_output=True, text=True)
    if res.returncode != 0:
        sys.exit(f"{label}: {' '.join(cmd)} failed:\n{res.stderr[-2000:]}")
    with open(out + ".json") as f:
        report = json.load(f)
    cells = {}
    for scene in report["scenes"]:
        for c in scene["classes"]:
            kernel = next(m for m in c["modes"] if m["mode"] == "kernel")
            cells[(scene["name"], c["class"])] = {
                "strahl": kernel["mrays"]["strahl"],
                "embree": kernel["mrays"]["embree"],
            }
    return report["machine"], cells


def spread(v):
    return {"median": statistics.median(v), "min": min(v), "max": max(v)}


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rounds", type=int, default=10)
    p.add_argument("--passes", type=int, default=3, help="timed passes per run (its best counts)")
    p.add_argument("--width", type=int, default=1024)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--out", help="write the figures as JSON here")
    p.add_argument("builds", nargs="+", type=parse_build, help="LABEL=PATH[,KEY=VALUE...]; the first is the reference")
    p.add_argument("scenes", nargs="*", default=[], help=argparse.SUPPRESS)
    argv = sys.argv[1:]
    scenes = []
    if "--" in argv:
        i = argv.index("--")
        argv, scenes = argv[:i], argv[i + 1:]
    args = p.parse_args(argv)
    if len(args.builds) < 2 or args.rounds < 1:
        sys.exit("need at least two builds and one round")
    runs = {b[0]: [] for b in args.builds}
    machines = {}
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(args.rounds):
            order = args.builds if k % 2 == 0 else list(reversed(args.builds))
            for b in order:
                machine, cells = run(b, scenes, args, tmp, k)
                machines[b[0]] = machine
                runs[b[0]].append(cells)
            print(f"round {k + 1}/{args.rounds} done", file=sys.stderr)
    ref = args.builds[0][0]
    keys = list(runs[ref][0].keys())
    result = {"rounds": args.rounds, "passes": args.passes, "width": args.width, "threads": args.threads, "machines": machines,
              "reference": ref, "cells": []}
    for label, _, env in args.builds[1:]:
        for key in keys:
            raw, norm, apis = [], [], {}
            for a, b in zip(runs[ref], runs[label]):
                sa, sb = best(a[key]["strahl"]), best(b[key]["strahl"])
                ea, eb = best(a[key]["embree"]), best(b[key]["embree"])
                raw.append(sb / sa)
                norm.append((sb / eb) / (sa / ea))
                for api in a[key]["strahl"]:
                    apis.setdefault(api, []).append(b[key]["strahl"][api] / a[key]["strahl"][api])
            result["cells"].append({
                "build": label, "env": env, "scene": key[0], "class": key[1],
                "best_ratio": spread(raw), "best_ratio_over_embree": spread(norm),
                "per_api_ratio": {api: spread(v) for api, v in apis.items()},
                "reference_best_mrays": spread([best(a[key]["strahl"]) for a in runs[ref]]),
                "build_best_mrays": spread([best(b[key]["strahl"]) for b in runs[label]]),
            })
    for label, machine in machines.items():
        print(f"- {label}: {machine}")
    print()
    print(f"| build ÷ {ref} | scene | class | {ref} best Mrays/s | build best Mrays/s | best ÷ best, median [range] "
          f"| divided by Embree's drift | packet | stream | single |")
    print("|---|---|---|---:|---:|---|---|---:|---:|---:|")
    fmt = lambda s: f"{s['median']:.3f} [{s['min']:.2f}–{s['max']:.2f}]"
    for c in result["cells"]:
        api = c["per_api_ratio"]
        print(f"| {c['build']} | {c['scene']} | {c['class']} | {c['reference_best_mrays']['median']:.1f} | "
              f"{c['build_best_mrays']['median']:.1f} | {fmt(c['best_ratio'])} | {fmt(c['best_ratio_over_embree'])} | "
              f"{api['packet']['median']:.3f} | {api['stream']['median']:.3f} | {api['single']['median']:.3f} |")
    if args.out:
        with open(args.out, "w") as f:
            json.dump(result, f, indent=1)


if __name__ == "__main__":
    main()
