#!/usr/bin/env python3
"""Regenerates README.md's results and accuracy tables and PERFORMANCE.md's standing table from
compare/results/results.json (one harness run): `python3 compare/fill_docs.py` after
`cargo run --release -p compare -- --shared --data --accuracy --scaling --out compare/results --json compare/results/results.json`.
The prose around the tables ("What these numbers say") is written by hand."""
import json, math, re, sys

root = sys.argv[1] if len(sys.argv) > 1 else "."
d = json.load(open(f"{root}/compare/results/results.json"))
commit = d["strahl_commit"]
date = d["date"]


def pct(x):
    return f"{100 * x:.4f}%"


def fnum(x):
    return f"{x:,}"


def mr(v):
    return f"{v:.1f}"


def apis(m):
    return " / ".join(mr(m[a]) for a in ("single", "packet", "stream"))


flat = [s for s in d["scenes"] if not s.get("instanced")]
inst = [s for s in d["scenes"] if s.get("instanced")]

out = []
def gi(x):
    return f"{x:.2f}×" if x is not None else "–"


def spread(q):
    mark = " ▲" if q[0] > 1 else (" ▼" if q[2] < 1 else "")
    return f"{q[1]:.2f} [{q[0]:.2f}–{q[2]:.2f}]{mark}"


out.append(
    f"Run of {date} on {d['machine']}, strahl commit `{commit}`, Embree 3.13.5, {d['threads']} threads, {d['passes']} timed passes per API and mode. "
    f"**Kernel mode** (each engine's native inputs prepared before the timed region): geometric mean of best-vs-best ratios "
    f"**{d['geomean_best_ratio']:.2f}×** over the flat scenes (of the per-class median pair ratios: {d['geomean_median_pair_ratio']:.2f}×), "
    f"**{gi(d['geomean_best_ratio_instanced'])}** over the instanced ones. **As called** (both fed from one SoA stream in the timed loop): "
    f"{d['geomean_best_ratio_as_called']:.2f}× over the flat scenes.\n"
)
out.append("Ratios are strahl/Embree speed. *best vs best*: each engine's fastest API, best pass against best pass; then the median and quartiles "
           "of the same ratio over the interleaved pass pairs (▲: faster, the lower quartile above 1; ▼: slower, the upper quartile below 1).\n")
out.append("| scene | class | rays | hit/miss agree | prim agree | t rel p99.9 | strahl single / packet / stream | Embree single / packet / stream | best vs best | pairs: median [q1–q3] | single vs single: median [q1–q3] | as called: best vs best |")
out.append("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
for s in flat:
    for c in s["classes"]:
        out.append(
            f"| {s['name']} | {c['class']} | {fnum(c['rays'])} | {pct(c['hit_miss_agreement'])} | {pct(c['prim_agreement'])} | "
            f"{c['t_rel_p999']:.1e} | {apis(c['mrays']['strahl'])} | {apis(c['mrays']['embree'])} | **{c['best_ratio']:.2f}×** | "
            f"{spread(c['best_ratio_spread'])} | {spread(c['single_ratio_spread'])} | {c['modes'][1]['best_ratio']:.2f}× |"
        )
out.append("\nMrays/s in kernel mode, best of the timed passes. Build (2 threads): best of interleaved rounds of all four builds, at least 5 and more while the rounds take under 0.3 s (up to 200):\n")
out.append("| scene | triangles | strahl ms | Embree MEDIUM ms | ratio | SAH strahl / Embree | strahl HIGH ms | Embree HIGH ms | HIGH ratio | SAH strahl HIGH / Embree HIGH | bytes/tri strahl / Embree, MEDIUM · HIGH |")
out.append("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
def f1(x):
    return f"{x:.1f}" if x is not None else "–"
def f2(x):
    return f"{x:.2f}" if x is not None else "–"
for s in flat:
    b = s["build"]
    out.append(
        f"| {s['name']} | {fnum(s['triangles'])} | {b['strahl_ms']:.2f} | {b['embree_ms']:.2f} | {s['build_ratio']:.2f}× | {f2(b['strahl_sah'])} / {f2(b.get('embree_sah'))} | "
        f"{b['strahl_high_ms']:.1f} | {b['embree_high_ms']:.1f} | {s['high_build_ratio']:.2f}× | {f2(b['strahl_high_sah'])} / {f2(b.get('embree_high_sah'))} | "
        f"{b['strahl_bytes_per_tri']:.1f} / {f1(b.get('embree_bytes_per_tri'))} · {b['strahl_high_bytes_per_tri']:.1f} / {f1(b.get('embree_high_bytes_per_tri'))} |"
    )
for s in flat:
    b = s["build"]
    both = b.get("embree_all_triangles")
    if both:
        kept = s["triangles"] - b["strahl_skipped_triangles"]
        out.append(
            f"\n{s['name']}: strahl's tree leaves out the {fnum(b['strahl_skipped_triangles'])} of its {fnum(s['triangles'])} triangles that can never be hit "
            f"(zero area or non-finite corners); Embree keeps them. Embree's SAH and bytes above are from builds over the {fnum(kept)} triangles strahl keeps; over all of them "
            f"they are {both[0]['sah']:.2f} and {both[0]['bytes_per_tri']:.1f} (MEDIUM), {both[1]['sah']:.2f} and {both[1]['bytes_per_tri']:.1f} (HIGH). "
            f"Build times are over all triangles for both engines."
        )
out.append("\n![strahl/Embree throughput ratio per scene and ray class](compare/results/ratio.png)\n")
out.append("### Instanced scenes\n")
out.append(
    "The same run, on the three instanced scene files in `data/` (Embree: one `RTC_GEOMETRY_TYPE_INSTANCE` per placement). "
    "The last column compares strahl instanced with strahl flattened on the same rays (forest and trio; the big world would need the memory below).\n"
)
out.append("| scene | class | rays | hit/miss agree | prim agree | strahl single / packet / stream | Embree single / packet / stream | best vs best | pairs: median [q1–q3] | single vs single | instanced vs flattened: hit/miss, same triangle, t ulps p50 / p99.9 |")
out.append("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---|")
for s in inst:
    for c in s["classes"]:
        fa = c.get("flat_agreement")
        fl = (
            f"{pct(fa['hit_miss_agreement'])}, {pct(fa['same_triangle'])}, {fa['t_ulps_median']:.0f} / {fa['t_ulps_p999']:.0f}"
            if fa
            else "–"
        )
        out.append(
            f"| {s['name']} | {c['class']} | {fnum(c['rays'])} | {pct(c['hit_miss_agreement'])} | {pct(c['prim_agreement'])} | "
            f"{apis(c['mrays']['strahl'])} | {apis(c['mrays']['embree'])} | **{c['best_ratio']:.2f}×** | {spread(c['best_ratio_spread'])} | {c['ratio']['single']:.2f}× | {fl} |"
        )
out.append("")
out.append("| scene | instances | placed triangles | stored triangles | strahl memory | flattened memory | build strahl / Embree ms |")
out.append("|---|---:|---:|---:|---:|---:|---:|")
for s in inst:
    i = s["instancing"]
    mib = lambda x: f"{x / 2**20:,.1f} MiB" if x < 2**30 else f"{x / 2**20:,.0f} MiB"
    fm = mib(i["flattened_memory_bytes"]) + ("" if i.get("flattened_measured") else " (estimated)")
    out.append(
        f"| {s['name']} | {fnum(i['instances'])} | {fnum(i['instanced_triangles'])} | {fnum(i['unique_triangles'])} | {mib(i['memory_bytes'])} | {fm} | {s['build']['strahl_ms']:.1f} / {s['build']['embree_ms']:.1f} |"
    )
out.append("\nInstanced against flattened with the forest moved by (T, T, T) (512×512 primary rays, secondary rays offset by `offset_ray_origin`):\n")
out.append("| T | class | hit/miss agree | same triangle | t ulps median | t ulps p99.9 |")
out.append("|---:|---|---:|---:|---:|---:|")
for t in d["instancing_translations"]:
    a = t["agreement"]
    out.append(
        f"| {t['translation']:.0e} | {t['class']} | {pct(a['hit_miss_agreement'])} | {pct(a['same_triangle'])} | {a['t_ulps_median']:.0f} | {a['t_ulps_p999']:.0f} |"
    )
out.append("\n### Scaling\n")
out.append(
    "The same run, on sphereflakes of one shape from 11 thousand to 11 million triangles (`--scaling`: 512×512 primary rays, best of 3 passes per mode, best of 2 builds). Best API per engine in kernel mode, Mrays/s strahl / Embree (ratio):\n"
)
out.append("| triangles | primary | shadow | diffuse | hit/miss agree (min) | build ms strahl / Embree (best of 2) | bytes/tri strahl / Embree |")
out.append("|---:|---:|---:|---:|---:|---:|---:|")
for s in d["scaling"]:
    cells = [f"{a:.1f} / {b:.1f} ({a / b:.2f}×)" for (_, a, b) in s["mrays"]]
    out.append(
        f"| {fnum(s['triangles'])} | {' | '.join(cells)} | {pct(s['hit_miss_agreement_min'])} | {s['strahl_build_ms']:.0f} / {s['embree_build_ms']:.0f} | {s['strahl_bytes_per_tri']:.1f} / {s['embree_bytes_per_tri']:.1f} |"
    )
out.append("\n![Mrays/s and build time against triangle count, both engines](compare/results/scaling.png)\n")
out.append("\n![The big world: 10,000 sphereflakes, 4.33 billion placed triangles, primary rays with shadows](compare/results/big_world.png)\n")
results = "\n".join(out)

a = d["accuracy"]
acc = [
    f"Leak test: {a['leak_test']}. Edge- and vertex-aimed rays: {', '.join(a['closed_meshes'])}. Speed: the run's ray sets on all flat scenes above (total rays / total best time, each engine on its faster of the single and packet APIs).\n",
    "| method | box test | Mrays/s primary / shadow / diffuse | leak rate at offset 0 / 1e3 / 1e4 / 1e5 / 1e6 | edge zero-hit | edge double-hit | vertex zero-hit | t error ulps median / p99.9 | agrees with Embree default / ROBUST | watertight |",
    "|---|---|---:|---:|---:|---:|---:|---:|---:|---|",
]


def sci(x):
    return "0" if x == 0 else f"{x:.1e}"


def leaks(m):
    return " / ".join(sci(m[k]) for k in ("0", "1e3", "1e4", "1e5", "1e6"))


for m in a["methods"]:
    wt = "**yes**" if m["watertight"] else "no"
    acc.append(
        f"| {m['name']} | {m['box_test']} | {m['mrays']['primary']:.1f} / {m['mrays']['shadow']:.1f} / {m['mrays']['diffuse']:.1f} | {leaks(m['leak_rate'])} | "
        f"{sci(m['edge_zero_hit_rate'])} | {sci(m['edge_double_hit_rate'])} | {sci(m['vertex_zero_hit_rate'])} | {m['t_ulp_median']:.0f} / {m['t_ulp_p999']:.0f} | "
        f"{pct(m['embree_default_agreement'])} / {pct(m['embree_robust_agreement'])} | {wt} |"
    )
for e in a["embree"]:
    wt = "yes" if all(v == 0 for v in e["leak_rate"].values()) and e["edge_zero_hit_rate"] == 0 and e["vertex_zero_hit_rate"] == 0 else "no"
    acc.append(
        f"| Embree {e['mode']} | | {e['mrays']['primary']:.1f} / {e['mrays']['shadow']:.1f} / {e['mrays']['diffuse']:.1f} | {leaks(e['leak_rate'])} | "
        f"{sci(e['edge_zero_hit_rate'])} | – | {sci(e['vertex_zero_hit_rate'])} | – | – | {wt} |"
    )
accuracy = "\n".join(acc)

readme = open(f"{root}/README.md").read()
readme = re.sub(r"<!-- results -->.*?<!-- /results -->", lambda _: f"<!-- results -->\n{results}\n<!-- /results -->", readme, flags=re.S)
readme = re.sub(
    r"<!-- accuracy table -->.*?<!-- /accuracy table -->", lambda _: f"<!-- accuracy table -->\n{accuracy}\n<!-- /accuracy table -->", readme, flags=re.S
)
open(f"{root}/README.md", "w").write(readme)

# PERFORMANCE.md standing table
geo = d["geomean_best_ratio"]
perf = [
    f"From the run in the README ({date}, commit `{commit}`, {d['machine']}, {d['threads']} threads, {d['width']}² primary rays, {d['passes']} timed passes per API and mode), "
    f"kernel mode (each engine's native inputs prepared before the timed region). Best API vs best API and the single-ray API against "
    f"`rtcIntersect1`/`rtcOccluded1`, each as the median [lower–upper quartile] of the interleaved pass pairs' ratios. Geometric mean of best vs best: "
    f"{geo:.2f}× over flat scenes, {gi(d['geomean_best_ratio_instanced'])} over instanced ones; as called, {d['geomean_best_ratio_as_called']:.2f}× over flat scenes.\n",
    "| scene | primary best / single | shadow best / single | diffuse best / single | build ratio MEDIUM / HIGH |",
    "|---|---:|---:|---:|---:|",
]
for s in d["scenes"]:
    cells = [f"{spread(c['best_ratio_spread'])} / {spread(c['single_ratio_spread'])}" for c in s["classes"]]
    name = s["name"] + (" (instanced)" if s.get("instanced") else "")
    hi = f" / {s['high_build_ratio']:.2f}×" if s.get("high_build_ratio") else ""
    perf.append(f"| {name} | {' | '.join(cells)} | {s['build_ratio']:.2f}×{hi} |")
p = open(f"{root}/PERFORMANCE.md").read()
start = p.index("## Current standing against Embree")
end = p.index("## Experiments")
p = p[:start] + "## Current standing against Embree\n\n" + "\n".join(perf) + "\n\n" + p[end:]
open(f"{root}/PERFORMANCE.md", "w").write(p)
print("ok", commit, date)
