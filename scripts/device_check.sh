#!/usr/bin/env bash
# One prepared run on a GPU machine: the device tests and the GPU benchmarks, each with the
# baseline it is judged against measured beside it, every result written under $OUT.
#
#   OUT=/some/folder bash scripts/device_check.sh        # on the GPU machine
#   DEVICE=cpu N=2 SCENE=1024 THROUGHPUT_N=32 CPU_WORKERS=1 DEVICE_WORKERS=1 bash scripts/device_check.sh  # dry run
#
# It installs nothing (such machines often reach no network): it runs the checkout with
# the machine's python3 (its CUDA build of torch) and the project on PYTHONPATH; numba,
# pandas, scikit-image, matplotlib, hypothesis and pytest-xdist must be there. Each step
# has its own time limit, so a slow one cannot eat the others' time: 9 min 40 s at most,
# inside one 10-minute device command. Compiling every numba kernel from an empty cache takes
# about 170 s of one core (a 2-core VM's); the warm step compiles them in one process per
# core (111 s on that VM's two), and a step cut short leaves what it compiled in the cache.
set -uo pipefail
OUT=${OUT:-device-out}
DEVICE=${DEVICE:-cuda}
N=${N:-64}                       # images of 1024^2 per CFAR batch (the 64 x 1024^2)
SCENE=${SCENE:-16384}            # the whole-scene side
THROUGHPUT_N=${THROUGHPUT_N:-2048}
CPU_WORKERS=${CPU_WORKERS:-1 4 8 16}  # the CPU side: one worker, and the counts to find its best
DEVICE_WORKERS=${DEVICE_WORKERS:-1 4 8}  # the device side likewise (each worker its own context)
PY=${PYTHON:-python3}
mkdir -p "$OUT"
export PYTHONPATH="$PWD:$PWD/eval${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
export TORCHSAR_CACHE="${TMPDIR:-/tmp}/torchsar-device-cache"  # $OUT keeps only the results

LOG="$OUT/log.txt"  # every step's output; with the CSVs, at most five files come back
: >"$LOG"
step() {  # step NAME LIMIT COMMAND...: run it, append its output to the log, note its exit
    local name=$1 limit=$2 start=$SECONDS
    shift 2
    echo "== $name (limit ${limit}s)" | tee -a "$LOG"
    timeout "$limit" "$@" >"$OUT/.step" 2>&1
    local code=$?
    cat "$OUT/.step" >>"$LOG"
    tail -n 15 "$OUT/.step"
    rm -f "$OUT/.step"
    echo "$name: exit $code after $((SECONDS - start)) s" | tee -a "$LOG" "$OUT/status.txt"
}

step machine 20 "$PY" -c "import torch, numba, sys; print(sys.version); print('torch', torch.__version__, 'cuda', torch.version.cuda, torch.cuda.is_available() and torch.cuda.get_device_name()); print('numba', numba.__version__); import triton; print('triton', triton.__version__)"
step warm 60 "$PY" scripts/warm_kernels.py
step device_tests 150 "$PY" -m pytest -q -p no:cacheprovider -o addopts=--import-mode=importlib tests/test_devices.py tests/cfar/test_gpu_kernels.py
step gpu_cfars 90 "$PY" scripts/benchmark.py --topic gpu --n "$N" --device "$DEVICE" --csv "$OUT/gpu_cfars.csv"
step scene 50 "$PY" scripts/scene_device.py --size "$SCENE" --device "$DEVICE" --tile 2048
step throughput_device 100 "$PY" scripts/benchmark.py --topic throughput --n "$THROUGHPUT_N" --workers $DEVICE_WORKERS --device "$DEVICE" --csv "$OUT/throughput_device.csv"
step throughput_cpu 110 "$PY" scripts/benchmark.py --topic throughput --n "$THROUGHPUT_N" --workers $CPU_WORKERS --csv "$OUT/throughput_cpu.csv"
echo "results in $OUT:"
ls "$OUT"
