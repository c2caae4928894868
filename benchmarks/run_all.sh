#!/usr/bin/env bash
# Every measurement of benchmarks/README.md (issue 12), one after the other, float32.
# Usage: bash benchmarks/run_all.sh [PYTHON]   (from the repository root; ~25 min on a quiet 2-core machine)
set -euo pipefail
PY=${1:-.venv/bin/python}
R=benchmarks/results
export PYTHONPATH=${PYTHONPATH:-$PWD}
$PY -m benchmarks.before_after --json $R/before_after_float32.json
# the streamed sweep (rollout_reduce) against the last commit that stored whole trajectories
$PY -m benchmarks.before_after --before b39f07b --kinds sweep --batch 8192 --steps 3000 \
  --json $R/before_after_sweep_float32.json > $R/before_after_sweep_float32.txt
for n in 1 2; do
  VCJAX_CPU_DEVICES=$n $PY -m vcjax.cli sweep benchmarks/configs/sweep_8192x3000.toml --no-x64 \
    --overwrite --out /tmp/vcjax-sweep-bench-$n 2> $R/sweep_8192x3000_devices$n.txt >/dev/null
  cp /tmp/vcjax-sweep-bench-$n/summary.json $R/sweep_8192x3000_devices$n.json
done
for t in sampled continuous; do
  for n in 1 2; do
    $PY -m benchmarks.throughput --timing $t --cpu-devices $n --batches 1 16 256 4096 16384 \
      --json $R/throughput_float32_${t}_${n}core.json > $R/throughput_float32_${t}_${n}core.txt
  done
done
$PY -m benchmarks.plot_throughput $R/throughput_float32_*core.json --out $R/throughput.png
$PY -m benchmarks.loops --loops infante --json $R/loops_float32.json > $R/loops_float32.txt
$PY -m benchmarks.loops --loops odin --batch 256 --steps 100 --json $R/loops_odin_float32.json \
  > $R/loops_odin_float32.txt
$PY -m benchmarks.loops --loops remus100 --batch 256 --steps 100 \
  --json $R/loops_remus100_float32.json > $R/loops_remus100_float32.txt
$PY -m benchmarks.numpy_remus100 --cpu-devices 2 --json $R/remus100_float32.json > $R/remus100_float32.txt
$PY -m benchmarks.cost_analysis --quick --json $R/cost_float32.json > $R/cost_float32.txt
$PY -m benchmarks.gradient_cost --batches 1024 --no-memory --json $R/gradient_b1024_float32.json \
  > $R/gradient_b1024_float32.txt
$PY -m benchmarks.gradient_cost --batches 1024 --no-memory --timing sampled \
  --json $R/gradient_b1024_sampled_float32.json > $R/gradient_b1024_sampled_float32.txt
$PY -m benchmarks.layout --json $R/layout_float32.json > $R/layout_float32.txt
# the unrolled small solves on the 6-DOF loops, against the commit before them
$PY -m benchmarks.loops_before_after --json $R/loops_linalg_before_after.json \
  > $R/loops_linalg_before_after.txt
# the tuner's gradient on a sharded batch: shared vs tiled gains
$PY -m benchmarks.sharded_gradient --json $R/sharded_gradient_float32.json \
  > $R/sharded_gradient_float32.txt
