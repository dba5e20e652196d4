#!/bin/bash
# §22 device run (one NVIDIA H200's 16-core host; the card not used): per-method, per-level
# cost of one thread, and thread scaling (issue 34 part 4). Output: percore_h200host_s22.jsonl.
# Run as benches/percore_tmp.py 20 1,2,4,8,16 48: the same code as benches/bench_per_thread.py.
set -x
lscpu | head -30; grep -m1 "model name" /proc/cpuinfo; ldd --version | head -1; which perf valgrind; nproc
export PYTHONPATH=$PWD/python
python -c "import idm_rs; print(idm_rs.core.engine.simd_level())"
timeout 330 python benches/bench_per_thread.py --side 20 --threads 1 2 4 8 16 --scale 48 > $OUT/percore_device.jsonl
cat $OUT/percore_device.jsonl
