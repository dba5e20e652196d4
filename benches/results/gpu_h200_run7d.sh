#!/usr/bin/env bash
# run 7's fourth call: kernel-only A/B of the generated kernel with the wave's numbers and the
# step loop's metrics in shared memory (LPS RK4: 96 registers, 8 B spilled on sm_90)
set -o pipefail
export PYTHONUNBUFFERED=1 PYTHONPATH=$PWD/python
timeout 200 python3 benches/bench_gpu.py --rows "" --late-rows "" --stiff 0 --cpu-points 0 --sample 32 --ab 512 \
  --ab-variants "default,wave+metrics shared" --variant-rows "wave+metrics shared=lps:rk4" \
  --json $OUT/gpu7d.json 2>&1 | grep -v '^{"nodes' | tee $OUT/log7d
