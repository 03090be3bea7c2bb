#!/usr/bin/env python3
"""Tables of bench/cluster_scaling.sh output (paper Table 1): per resolution and worker count,
kernel and rendering efficiency frame by frame against the 1-worker run on the same frames.

  kernel efficiency of frame k    = K1(k) / (N x max_i K_i(k))   (K1: the single worker's kernel)
  rendering efficiency of frame k = R1(k) / (N x max_i R_i(k))
  balance                         = max_i K_i / mean_i K_i
  kernel sum                      = sum_i K_i / K1   (1.00: the tiles cost what the whole frame does)
  machine slowdown                = median kernel of N concurrent single-threaded whole-frame
                                    renders / the kernel of one alone (the control run: what
                                    sharing the machine costs each process, with no cluster)
  net kernel efficiency           = kernel efficiency x machine slowdown

Frames with a recovered task (a late or lost worker) are left out and counted. Runs of several
predictors (VARIANTS in cluster_scaling.sh: SIZE-nN-VARIANT-rK) are rows of their own, each
compared with the same 1-worker run; each row also gives the master's predictor counts and its
median reprojection time.

  python3 bench/cluster_scaling_report.py OUTDIR [--jsonl FILE]   (FILE: every frame, one line each)
"""
import glob, json, os, re, statistics, sys

out = sys.argv[1]
jsonl = sys.argv[sys.argv.index("--jsonl") + 1] if "--jsonl" in sys.argv else None
runs = {}  # (size, n, variant) -> {frame: cluster_frame event}
recovered = {}
for path in glob.glob(os.path.join(out, "*-n*.master.err")):
    m = re.match(r"(\d+x\d+)-n(\d+)(-.*)?\.master\.err", os.path.basename(path))
    key = (m.group(1), int(m.group(2)), (m.group(3) or "")[1:])
    frames = {}
    for line in open(path):
        if '"cluster_frame"' not in line:
            continue
        e = json.loads(line)
        if e["recovered"]:
            recovered[key] = recovered.get(key, 0) + 1
            continue
        frames[e["cluster_frame"]] = e
    # Only the frames loadtest counted (after its warm-up; not the ones it had requested ahead).
    load = path.replace(".master.err", ".load")
    counted = {json.loads(l)["frame"] for l in open(load) if l.startswith('{"client"')} if os.path.exists(load) else set()
    runs[key] = {k: e for k, e in frames.items() if k in counted}
summary = json.load(open(os.path.join(out, "summary.json")))

def slowdown(size, n):
    def kernels(m):
        p = os.path.join(out, "%s-control-n%d.json" % (size, m))
        return [json.loads(l)["kernel_ms"] for l in open(p) if l.strip()] if os.path.exists(p) else []
    one, many = kernels(1), kernels(n)
    return statistics.median(many) / one[0] if one and many else float("nan")

def fps(size, n, variant=""):
    p = os.path.join(out, "%s-n%d%s.load" % (size, n, "-" + variant if variant else ""))
    for line in open(p) if os.path.exists(p) else []:
        if '"summary"' in line:
            return json.loads(line)["fps_total"]
    return float("nan")

rows = []
for size in sorted({k[0] for k in runs}, key=lambda s: int(s.split("x")[0])):
    ref = runs.get((size, 1, ""), {})
    print("### %s, AO %s, %s, loop %s\n" % (size, summary["ao"], summary["scene"], summary.get("loop", "")))
    print("| workers | run | frames | kernel eff. median (worst) | rendering eff. median (worst) | balance median (worst) | kernel sum / single | machine slowdown | net kernel eff. | fps | predictors | reproject ms |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for (_, n, variant) in sorted(k for k in runs if k[0] == size):
        ke, re_, bal, ksum, preds, rep_ms = [], [], [], [], {}, []
        for k, e in sorted(runs[(size, n, variant)].items()):
            if k not in ref:
                continue
            k1 = ref[k]["per_node"][0]["kernel_ms"]
            r1 = ref[k]["per_node"][0]["rendering_ms"]
            ks = [p["kernel_ms"] for p in e["per_node"]]
            rs = [p["rendering_ms"] for p in e["per_node"]]
            nodes = len(ks)
            pred = e.get("predictor", "")
            preds[pred] = preds.get(pred, 0) + 1
            if pred == "reprojected":
                rep_ms.append(e.get("reproject_ms", 0))
            row = {"size": size, "workers": n, "run": variant, "predictor": pred, "reproject_ms": e.get("reproject_ms"), "reproject_cpu_ms": e.get("reproject_cpu_ms"), "frame": k, "kernel_eff": k1 / (nodes * max(ks)),
                   "rendering_eff": r1 / (nodes * max(rs)), "balance": e["balance"], "kernel_sum": sum(ks) / k1,
                   "kernel_ms": ks, "rendering_ms": rs, "single_kernel_ms": k1, "single_rendering_ms": r1}
            rows.append(row)
            ke.append(row["kernel_eff"]); re_.append(row["rendering_eff"]); bal.append(e["balance"]); ksum.append(row["kernel_sum"])
        if not ke:
            continue
        pct = lambda xs, worst: "%.1f%% (%.1f%%)" % (100 * statistics.median(xs), 100 * worst(xs))
        rec = recovered.get((size, n, variant), 0)
        sd = slowdown(size, n)
        print("| %d | %s | %d%s | %s | %s | %.3f (%.3f) | %.3f | %.3f | %.1f%% | %.2f | %s | %s |" % (
            n, variant or "-", len(ke), " (+%d recovered)" % rec if rec else "", pct(ke, min), pct(re_, min),
            statistics.median(bal), max(bal), statistics.median(ksum), sd, 100 * statistics.median(ke) * sd,
            fps(size, n, variant), " ".join("%s %d" % kv for kv in sorted(preds.items())),
            "%.2f" % statistics.median(rep_ms) if rep_ms else "-"))
    print()
print("Conditions: " + ", ".join("%s %s" % (k, v) for k, v in summary.items() if k != "summary"))
if jsonl:
    with open(jsonl, "w") as f:
        f.write(json.dumps(summary) + "\n")
        for r in rows:
            f.write(json.dumps(r) + "\n")
