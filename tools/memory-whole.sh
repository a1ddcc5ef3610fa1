#!/bin/bash
# Whole runs' peak memory against the up-front estimate (docs/benchmarks/memory.md): the band
# methods' footprints are fitted to these. Each run is one `cellflip run` process under
# /usr/bin/time (its maximum RSS is the run's peak); the estimate is the one its summary prints.
# One CSV line per run, with the particles the run held after a step (least and most), which
# is what a band method's estimate has to foresee.
# Usage: tools/memory-whole.sh [-b path/to/cellflip] [-d seconds] method,scene,res ...
#   e.g. tools/memory-whole.sh ccp,drop-3d,64 nbflip,dam-3d,96
set -euo pipefail
B=target/release/cellflip
DURATION=1
while getopts "b:d:" opt; do
  case $opt in
    b) B=$OPTARG ;;
    d) DURATION=$OPTARG ;;
    *) exit 2 ;;
  esac
done
shift $((OPTIND - 1))
[ $# -gt 0 ] || { echo "usage: $0 [-b cellflip] [-d seconds] method,scene,res ..." >&2; exit 2; }
echo "method,scene,res,duration_s,peak_mib,wall_s,held_least,held_most,estimate_mib"
for spec in "$@"; do
  IFS=, read -r m s r <<<"$spec"
  log=$(mktemp)
  /usr/bin/time -f "MAXRSS %M WALL %e" -o "$log.time" \
    "$B" run "$s" --res "$r" --method "$m" --duration "$DURATION" --no-record >"$log"
  peak=$(($(grep -oP 'MAXRSS \K[0-9]+' "$log.time") / 1024))
  wall=$(grep -oP 'WALL \K[0-9.]+' "$log.time")
  held=$(grep -oP '\(\K[0-9]+ \.\. [0-9]+(?= after a step)' -m1 "$log" | tr -s ' .' ',')
  est=$(grep -oP 'estimated up front \K[0-9]+' "$log")
  echo "$m,$s,$r,$DURATION,$peak,$wall,$held,$est"
  rm -f "$log" "$log.time"
done
