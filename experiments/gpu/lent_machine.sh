#!/usr/bin/env bash
# One call on a lent GPU machine (a bare CUDA image without ../shared), about 7 minutes: the CUDA
# tests, the training and data rows, the default command, where training and a fit wait for the
# GPU, the paper preset's step in variants, and the paper preset's fit of cat; every line also
# lands in $OUT/log, with each part's seconds.
#   here:   bash ../shared/tools/gpu-prep.sh          (packs .gpu/: wheels and two DiLiGenT crops)
#   there:  bash experiments/gpu/lent_machine.sh       (with .gpu/ carried along; writes under $OUT)
set -u
out=${OUT:-runs/gpu}
mkdir -p "$out"
exec > >(tee "$out/log") 2>&1
python3 -m pip install -q --no-index --no-deps --target /tmp/site .gpu/whl/*.whl
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1
mkdir -p .gpu/diligent && ln -sfn "$PWD/.gpu/data" .gpu/diligent/pmsData_crop
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader
gpu="python3 experiments/gpu/run.py --out $out --diligent .gpu/diligent"
part() {   # part <seconds> <label> <command…>: run it within the limit, say how long it took
  local limit=$1 label=$2; shift 2
  local start=$SECONDS
  timeout "$limit" "$@"
  echo "[$label: $((SECONDS - start)) s, exit $?]"
}
part 100 tests python3 -m pytest -q -p no:cacheprovider tests/test_device.py tests/test_training_data.py \
  tests/test_geometry.py 2>&1 | tail -3
part 150 "train, data" $gpu --rows train data 2>&1 | grep "^|\|^\["
part 100 default $gpu --rows default --subjects cat 2>&1 | grep "^|\|^\["
part 100 syncs $gpu --rows syncs --train-steps 20 2>&1 | grep "^|\|^\["
part 80 fitstep $gpu --rows fitstep --subjects cat 2>&1 | grep -v "^  running\|^machine\|self.log"
part 120 paper $gpu --rows paper --subjects cat 2>&1 | grep "^|\|^\["
# what comes back: the log, each run's metrics.json and fit.log, not its checkpoints and arrays
find "$out" \( -name "*.ckpt" -o -name "*.npy" -o -name "*.ply" -o -name "events.out.*" \) -delete
