import json, subprocess, statistics, sys
bins = {"native_before": "/tmp/compare_native_before", "dependency_before": "/tmp/compare_portable_before",
        "native_after": "/tmp/compare_native_after", "dependency_after": "/tmp/compare_portable_after"}
rounds = int(sys.argv[1])
res = {k: [] for k in bins}
for r in range(rounds):
    order = list(bins) if r % 2 == 0 else list(reversed(bins))
    for k in order:
        out = f"/tmp/sph_{k}_{r}"
        subprocess.run([bins[k], "--spheres", "--sphere-levels", "6", "--passes", "3", "--out", out], check=True, capture_output=True, cwd="/work/main")
        d = json.load(open(out + "/spheres.json"))
        cells = {}
        for c in d["engines"][0]["classes"]:
            for a in c["apis"]:
                cells[(c["class"], a["api"])] = (a["strahl"], a["embree"])
        for m in d["methods"]:
            cells[("level3 " + m["test"], "stream")] = (m["mrays"], None)
        res[k].append(cells)
    print("round", r, file=sys.stderr)
keys = list(res["native_before"][0])
print("| cell | " + " | ".join(bins) + " | dependency_after ÷ native_after | dependency_before ÷ native_before |")
print("|---|" + "---:|" * (len(bins) + 2))
for key in keys:
    med = {k: statistics.median(x[key][0] for x in res[k]) for k in bins}
    ra = statistics.median(a[key][0] / b[key][0] for a, b in zip(res["dependency_after"], res["native_after"]))
    rb = statistics.median(a[key][0] / b[key][0] for a, b in zip(res["dependency_before"], res["native_before"]))
    print(f"| {key[0]} {key[1]} | " + " | ".join(f"{med[k]:.1f}" for k in bins) + f" | {ra:.2f} | {rb:.2f} |")
json.dump({k: [{f"{a} {b}": v for (a, b), v in x.items()} for x in res[k]] for k in res}, open("/tmp/sph_builds.json", "w"), indent=1)
