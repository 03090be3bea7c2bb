#!/usr/bin/env python3
"""One table of bench/cluster_predictors.sh runs (their jsonl, concatenated per run): per loop,
size and worker count, the previous-frame predictor against the reprojected one, run by run.

  balance      = median over frames of max_i K_i / mean_i K_i (the workers' kernels of one frame:
                 measured within the frame, so the 1-worker reference's own drift does not enter)
  kernel eff.  = median over frames of K1(k) / (N x max_i K_i(k)) (K1: the 1-worker run's kernel
                 of the same frame; carries that reference's drift and the machine's slowdown)
  fps          = the loadtest client's frame rate (the master's reprojection time included)

  python3 bench/cluster_predictors_summary.py RUN1.jsonl [RUN2.jsonl ...]
"""
import json, statistics, sys

def load(path):
    rows, loop = [], None
    for line in open(path):
        d = json.loads(line)
        if d.get("summary"):
            loop = d["loop"].split("/")[-1].replace(".json", "").replace("pavilion-", "")
            continue
        if d["workers"] == 1:
            continue
        d["loop"] = loop
        rows.append(d)
    return rows

runs = [load(p) for p in sys.argv[1:]]
keys = sorted({(r["loop"], r["size"], r["workers"]) for rows in runs for r in rows},
              key=lambda k: (k[0], int(k[1].split("x")[0]), k[2]))
med = lambda xs: statistics.median(xs) if xs else float("nan")
print("| loop | size | workers | balance, previous | balance, reprojected | kernel eff., previous | kernel eff., reprojected | reproject ms |")
print("|---|---|---|---|---|---|---|---|")
better = total = 0
for loop, size, n in keys:
    cells = {"previous": ([], []), "reproject": ([], [])}
    rep_ms = []
    for rows in runs:
        for v in cells:
            sel = [r for r in rows if (r["loop"], r["size"], r["workers"]) == (loop, size, n) and r["run"].startswith(v)]
            cells[v][0].append(med([r["balance"] for r in sel]))
            cells[v][1].append(med([r["kernel_eff"] for r in sel]))
            if v == "reproject":
                rep_ms += [r["reproject_ms"] for r in sel if r.get("reproject_ms")]
    for a, b in zip(cells["previous"][0], cells["reproject"][0]):
        total += 1
        better += b < a
    fmt_b = lambda xs: " / ".join("%.3f" % x for x in xs)
    fmt_e = lambda xs: " / ".join("%.1f%%" % (100 * x) for x in xs)
    print("| %s | %s | %d | %s | %s | %s | %s | %.2f |" % (loop, size, n, fmt_b(cells["previous"][0]), fmt_b(cells["reproject"][0]),
                                                          fmt_e(cells["previous"][1]), fmt_e(cells["reproject"][1]), med(rep_ms)))
print("\nReprojected balance lower than the previous frame's in %d of %d (loop, size, workers, run) cells." % (better, total))
