#!/usr/bin/env bash
# issue 53: the generated kernel with the point's branch decisions as bits of its FLAGS word
# (the lean step in the generator): kernel-only A/B and the 10^6-point LPS rows; compare with
# run 7 (gpu_h200_run7*.json, the same kernel without the flags)
set -o pipefail
export PYTHONUNBUFFERED=1 PYTHONPATH=$PWD/python
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader | tee $OUT/log8
timeout 240 python3 benches/bench_gpu.py --rows "lps:auto,lps:rk4,dps:auto" --late-rows "" --stiff 0 --cpu-points 0 \
  --sample 32 --ab 512 --ab-variants "default,wave+metrics shared" --json $OUT/gpu8.json 2>&1 | tee -a $OUT/log8
timeout 100 python3 -m pytest -q -p no:cacheprovider -o addopts="" tests/test_gpu_kernel.py -k "gpu_equals" \
  2>&1 | tail -4 | tee -a $OUT/log8
