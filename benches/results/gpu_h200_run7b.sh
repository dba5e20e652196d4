#!/usr/bin/env bash
# run 7's second call: the kernel-only A/B (block 32 against 64 beyond the LPS), and the
# per-effect GPU-equals-CPU-build test with its messages
set -o pipefail
export PYTHONUNBUFFERED=1 PYTHONPATH=$PWD/python
timeout 150 python3 -m pytest -q -p no:cacheprovider -o addopts="" tests/test_gpu_kernel.py -k "each_effect and gpu" \
  --tb=short 2>&1 | grep -v "^E  *[-0-9.e, \[\]arys(]*$" | tail -60 | tee $OUT/log7b
timeout 200 python3 benches/bench_gpu.py --rows "" --late-rows "" --stiff 0 --cpu-points 0 --ab 512 \
  --ab-variants "default,block 32" --json $OUT/gpu7b.json 2>&1 | grep -v '^{"nodes' | tee -a $OUT/log7b
