#!/usr/bin/env python3
"""Tables and a plot from bench/display_network.sh's JSON lines.

Usage: bench/display_network_report.py LINES.jsonl [MORE.jsonl ...] [PLOT.png]
Prints the markdown tables (one row per link and display) and, with gnuplot installed and a
PLOT path given, draws frames/s and input-to-frame latency per link, one curve per display.
A row of a later file replaces the row of the same link and display of an earlier one (say, a
second run of one display); each file's conditions are printed.
"""
import json
import os
import subprocess
import sys
import tempfile

NAMES = {"jpeg": "JPEG q85", "s3tc": "S3TC", "mjpeg": "MJPEG*", "h264": "H.264"}


def main():
    files = [a for a in sys.argv[1:] if a.endswith(".jsonl")]
    plot = next((a for a in sys.argv[1:] if a.endswith(".png")), None)
    rows, runs, source = [], [], []  # source[i]: the file rows[i] came from
    for path in files:
        lines = [json.loads(l) for l in open(path) if l.strip()]
        runs.append((path, next(l for l in lines if "load_start" in l), next((l for l in lines if "load_end" in l), {})))
        for r in (l for l in lines if "display" in l):
            key = (r["mbit_s"], r["rtt_ms"], r["loss_percent"], r["display"])
            at = next((i for i, o in enumerate(rows) if (o["mbit_s"], o["rtt_ms"], o["loss_percent"], o["display"]) == key), None)
            if at is None:
                rows.append(r)
                source.append(path)
            else:
                rows[at] = r
                source[at] = path
    _, head, end = runs[0]
    hz = head.get("request_hz", 0)
    if hz:  # a browser-like client: requests on a clock, no one-request phase
        print(f"Link: {head['link']}; scene {head['scene']}, {head['size'].replace(' ', 'x')}, AO {head['ao']}; a frame "
              f"asked for every {1000 / hz:.0f} ms for {head['seconds']} s per row; {head['isa']}, {head['cores']} cores, "
              f"load {head['load_start']} at the start and {end.get('load_end', '?')} at the end.\n")
        print("| Mbit/s | RTT ms | loss % | display | frames/s | bytes per frame | latency ms median (p90) "
              "| requests merged by the node | frames sent by the node |")
        print("|---|---|---|---|---|---|---|---|---|")
        for r in rows:
            print(f"| {r['mbit_s']:g} | {r['rtt_ms']:g} | {r['loss_percent']:g} | {NAMES.get(r['display'], r['display'])} "
                  f"| {r['fps']:.1f} | {r['bytes_per_frame']:,.0f} | {r['latency_2_ms']:,.0f} ({r['p90_latency_2_ms']:,.0f}) "
                  f"| {r['node_dropped']} | {r['node_frames']} |")
        return
    for path, h, e in runs:
        shown = sorted({r["display"] for r, p in zip(rows, source) if p == path})
        print(f"`{os.path.basename(path)}` ({', '.join(NAMES.get(d, d) for d in shown)} rows): link {h['link']}; "
              f"scene {h['scene']}, {h['size'].replace(' ', 'x')}, AO {h['ao']}; {h['seconds']} s windows and "
              f"{h['latency_seconds']} s of one-request latency per row; {h['isa']}, {h['cores']} cores, load "
              f"{h['load_start']} at the start and {e.get('load_end', 'not recorded')} at the end.\n")
    print("| Mbit/s | RTT ms | loss % | display | frames/s | bytes per frame | encode ms | latency ms (p90), 2 outstanding "
          "| latency ms (p90), 1 outstanding | transfer ms | bound: RTT + rendering + 30 | within | rest ms |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        transfer = r["bytes_per_frame"] * 8 / (r["mbit_s"] * 1e3) if r["bytes_per_frame"] else None
        fmt = lambda v, d=1: "-" if v is None else f"{v:,.{d}f}"
        within = {True: "yes", False: "no", None: "-"}[r["within_bound"]]
        # What the latency holds beyond the round trip, the rendering and the frame's transfer
        # at the link's rate: encoding, the node's own steps, queueing, TCP's losses.
        rest = (r["latency_ms"] - (r["rtt_ms"] or 0) - r["latency_rendering_ms"] - transfer
                if transfer is not None and r["latency_ms"] else None)
        print(f"| {r['mbit_s']:g} | {fmt(r['rtt_ms'], 0)} | {fmt(r['loss_percent'], 0)} | {NAMES.get(r['display'], r['display'])} "
              f"| {fmt(r['fps'])} | {fmt(r['bytes_per_frame'], 0)} | {fmt(r['encode_ms'])} "
              f"| {fmt(r['latency_2_ms'], 0)} ({fmt(r['p90_latency_2_ms'], 0)}) | {fmt(r['latency_ms'], 0)} ({fmt(r['p90_latency_ms'], 0)}) "
              f"| {fmt(transfer, 0)} | {fmt(r['latency_bound_ms'], 0)} | {within} | {fmt(rest, 0)} |")
    if not plot:
        return
    links = []
    for r in rows:
        key = (r["mbit_s"], r["rtt_ms"], r["loss_percent"])
        if key not in links:
            links.append(key)
    displays = [d for d in NAMES if any(r["display"] == d for r in rows)]
    with tempfile.TemporaryDirectory() as tmp:
        data = os.path.join(tmp, "d.dat")
        with open(data, "w") as f:
            f.write("# link " + " ".join(f"{d}_fps {d}_lat {d}_bound" for d in displays) + "\n")
            for i, key in enumerate(links):
                label = f"{key[0]:g}/{key[1]:g}/{key[2]:g}" if key[1] is not None else f"{key[0]:g}"
                vals = []
                for d in displays:
                    r = next((r for r in rows if r["display"] == d and (r["mbit_s"], r["rtt_ms"], r["loss_percent"]) == key), None)
                    vals += [r["fps"], r["latency_ms"] or "NaN", r["latency_bound_ms"] or "NaN"] if r else ["NaN"] * 3
                f.write(f"{i} \"{label}\" " + " ".join(str(v) for v in vals) + "\n")
        fps_plots = ", ".join(f"'{data}' using 1:{3 + 3 * k}:xtic(2) with linespoints title '{NAMES[d]}'"
                              for k, d in enumerate(displays))
        lat_plots = ", ".join(f"'{data}' using 1:{4 + 3 * k}:xtic(2) with linespoints title '{NAMES[d]}'"
                              for k, d in enumerate(displays))
        bound = f"'{data}' using 1:5:xtic(2) with lines dashtype 2 lc rgb 'black' title 'RTT + rendering + 30 ms (JPEG)'"
        script = f"""
set terminal pngcairo size 1400,900 font ',10'
set output '{plot}'
set multiplot layout 2,1 title 'Displays over emulated links ({head['link']}): {os.path.basename(head['scene'])}, {head['size'].replace(' ', 'x')}; x: Mbit/s / RTT ms / loss %'
set xtics rotate by -45
set grid
set key outside right
set ylabel 'frames/s delivered (2 requests outstanding)'
plot {fps_plots}
set logscale y
set ylabel 'input to frame, ms (1 request outstanding)'
plot {lat_plots}, {bound}
unset multiplot
"""
        subprocess.run(["gnuplot"], input=script.encode(), check=True)


if __name__ == "__main__":
    main()
