#!/usr/bin/env bash
# run 7's third call: the per-effect GPU-equals-CPU-build test at up to 80 V (converged points)
set -o pipefail
export PYTHONUNBUFFERED=1 PYTHONPATH=$PWD/python
timeout 150 python3 -m pytest -q -p no:cacheprovider -o addopts="" tests/test_gpu_kernel.py -k "gpu_equals" \
  --tb=short 2>&1 | tail -40 | tee $OUT/log7c
