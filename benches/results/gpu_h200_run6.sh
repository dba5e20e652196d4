#!/usr/bin/env bash
# verification of the shipped kernel (issue32 145c26d) as one piece on the GPU
set -o pipefail
cd "$(dirname "$0")"
export PYTHONUNBUFFERED=1
nvidia-smi --query-gpu=name --format=csv,noheader | tee $OUT/log6
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --target /tmp/site idm_rs-*.whl 2>&1 | tail -3
cp -r py/idm_rs/. /tmp/site/idm_rs/
cp v6/gpu/* /tmp/site/idm_rs/gpu/
export PYTHONPATH=/tmp/site
cd v6
timeout 150 python3 -m pytest -q -p no:cacheprovider -o addopts="" tests/test_gpu_kernel.py -k "gpu_equals or nvrtc" 2>&1 | tail -5 | tee -a $OUT/log6
timeout 150 python3 bench_gpu.py --rows "lps:rk4,lps:auto" --late-rows "" --stiff 0 --cpu-points 0 --sample 64 --json $OUT/rows6.json 2>&1 | grep -v '^{"nodes' | tee -a $OUT/log6
