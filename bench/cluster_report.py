#!/usr/bin/env python3
"""Table of bench/cluster_bench.sh output: kernel and rendering efficiency per worker count
against the 1-worker run on the same camera-loop frames, balance, fps.
  python3 bench/cluster_report.py docs/results/cluster.jsonl"""
import json, statistics, sys

rows = [json.loads(l) for l in open(sys.argv[1]) if l.strip()]
frames, loads, summary = {}, {}, {}
for r in rows:
    if r.get("summary"): summary = r
    elif "loadtest" in r: loads[r["run"]] = r["loadtest"]
    else: frames.setdefault(r["run"], []).append(r)

ref = {}  # frame -> (kernel, rendering) of the single worker
for f in frames.get("n1", []):
    ref[f["frame"]] = (f["per_node"][0]["kernel_ms"], f["per_node"][0]["rendering_ms"])

def med(xs): return statistics.median(xs) if xs else float("nan")

print("| run | nodes | frames | kernel eff. | rendering eff. | balance (max/mean) | fps total |")
print("|---|---|---|---|---|---|---|")
for run in ["n1", "n2", "n3", "n4", "hetero", "clients3"]:
    fs = [f for f in frames.get(run, []) if f["frame"] > 1 and f["recovered"] == 0]
    if not fs: continue
    n = len(fs[0]["per_node"])
    ke, re_ = [], []
    if run != "hetero":
        for f in fs:
            if f["frame"] not in ref: continue
            k1, r1 = ref[f["frame"]]
            kmax = max(p["kernel_ms"] for p in f["per_node"])
            rmax = max(p["rendering_ms"] for p in f["per_node"])
            ke.append(k1 / (n * kmax)); re_.append(r1 / (n * rmax))
    fmt = lambda xs: "%.1f%%" % (100 * med(xs)) if xs else "—"
    fps = loads.get(run, {}).get("fps_total", float("nan"))
    print("| %s | %d | %d | %s | %s | %.3f | %.2f |" % (run, n, len(fs), fmt(ke), fmt(re_), med([f["balance"] for f in fs]), fps))
print()
print("Conditions: " + ", ".join("%s %s" % (k, v) for k, v in summary.items() if k != "summary"))
