#!/bin/bash
# Wall time of `ffls render CAP --probe sunrise --turntable TT`, a reference tree against this one,
# alternating run by run, and whether their frames are the same bytes.
# usage: benchmarks/render_ab.sh CAP ROUNDS TURNTABLE BEFORE_TREE   (python: the venv's)
export OMP_NUM_THREADS=1
CAP=$1; N=$2; TT=$3; BEFORE=$4; AFTER=$(cd "$(dirname "$0")/.." && pwd)
for r in $(seq 1 $N); do
  for which in main new; do
    if [ $which = main ]; then PP=$BEFORE; else PP=$AFTER; fi
    rm -rf /tmp/render_ab_$which
    s=$(date +%s.%N)
    PYTHONPATH=$PP python -m ffls render $CAP --probe sunrise --turntable $TT -o /tmp/render_ab_$which > /dev/null 2>&1 || echo FAIL $which
    e=$(date +%s.%N)
    echo "$r $which $(echo "$e - $s" | bc)"
  done
  cmp -s <(cat /tmp/render_ab_main/*) <(cat /tmp/render_ab_new/*) && echo "round $r identical" || echo "round $r DIFFER"
done
