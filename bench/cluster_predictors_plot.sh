#!/usr/bin/env bash
# Plots bench/cluster_predictors.sh's frames: split efficiency per frame (1 / balance, the
# largest worker kernel against the mean, within the frame) with the previous-frame predictor and
# with reprojection, per loop and size at WORKERS workers. All repetitions of a run are drawn.
#
#   bench/cluster_predictors_plot.sh RUN.jsonl OUT.png [WORKERS=15]
set -euo pipefail
in=$1 out=$2 n=${3:-15}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
python3 - "$in" "$tmp" "$n" <<'PY'
import json, sys
src, tmp, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
loop, series = None, {}
for line in open(src):
    d = json.loads(line)
    if d.get("summary"):
        loop = d["loop"].split("/")[-1].replace(".json", "").replace("pavilion-", "")
        continue
    if d["workers"] != n or not d["run"]:
        continue
    key = (loop, d["size"], d["run"])
    series.setdefault(key, []).append((d["frame"], 100.0 / d["balance"]))
panels = sorted({(l, s) for l, s, _ in series}, key=lambda p: (p[0], int(p[1].split("x")[0])))
with open(tmp + "/panels", "w") as f:
    for i, (l, s) in enumerate(panels):
        runs = sorted(r for (ll, ss, r) in series if (ll, ss) == (l, s))
        f.write("%s %s %s\n" % (l if l != "camera-loop" else "shared", s, " ".join(runs)))
        for r in runs:
            with open("%s/p%d-%s.dat" % (tmp, i, r), "w") as g:
                for k, v in sorted(series[(l, s, r)]):
                    g.write("%d %.3f\n" % (k, v))
PY
rows=$(wc -l < "$tmp/panels")
{
  echo "set terminal pngcairo size 1500,$((260 * ((rows + 1) / 2))) font \",9\""
  echo "set output \"$out\""
  echo "set multiplot layout $(((rows + 1) / 2)),2"
  echo "set grid; set yrange [50:102]; set ylabel \"100 / balance (%)\"; set xlabel \"loop frame\"; set key bottom left font \",8\""
  i=0
  while read -r loop size runs; do
    echo "set title \"$loop loop, $size, $n workers: previous frame (grey) vs reprojected (blue)\""
    plot="plot"
    for r in $runs; do
      if [[ $r == previous* ]]; then style="lc rgb \"#888888\""; else style="lc rgb \"#1f5fbf\""; fi
      plot="$plot \"$tmp/p$i-$r.dat\" u 1:2 w lp pt 7 ps 0.5 $style t \"$r\","
    done
    echo "${plot%,}"
    i=$((i + 1))
  done < "$tmp/panels"
  echo "unset multiplot"
} | gnuplot
echo "wrote $out"
