#!/usr/bin/env bash
# issue 53 on a card: the kernel with the right-hand side generated from the engine's model —
# throughput (bench first), then the GPU-equals-its-CPU-build tests, every effect included.
# Run from the repository root with python/idm_rs/_core.abi3.so carried (abi3 build).
set -o pipefail
export PYTHONUNBUFFERED=1 PYTHONPATH=$PWD/python
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader | tee $OUT/log7
timeout 290 python3 benches/bench_gpu.py --rows "lps:auto,lps:rk4,dps:auto,dps5:auto" --late-rows "" \
  --stiff 0 --cpu-points 16384 --sample 128 --ab 512 --ab-variants "default,block 32" \
  --effect-rows "lps:auto,dps:auto" --json $OUT/gpu7.json 2>&1 | tee -a $OUT/log7
timeout 150 python3 -m pytest -q -p no:cacheprovider -o addopts="" tests/test_gpu_kernel.py -k "gpu_equals" \
  2>&1 | tail -15 | tee -a $OUT/log7
