#!/usr/bin/env bash
# One call on a lent GPU machine (a bare CUDA image without ../shared), at most 9 minutes: the CUDA
# tests, the paper preset's fits of cat and pot1 with the true lights as it runs on a GPU (networks
# in bfloat16, to set beside the fast preset's), the training
# and data rows, where rendering the training data spends the GPU's time, a fresh process's
# start-up and the default command; every line also lands in $OUT/log, with each part's seconds.
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
part 80 tests python3 -m pytest -q -p no:cacheprovider tests/test_device.py tests/test_training_data.py \
  tests/test_inverse.py -k "test_device or gpu or batch or bf16 or second" 2>&1 | tail -3
part 220 paper $gpu --rows paper --subjects cat pot1 --fit-precisions bf16-mixed 2>&1 | grep "^|\|^\["
part 110 "train, data" $gpu --rows train data --precisions 32-true 2>&1 | grep "^|\|^\["
part 40 render $gpu --rows render 2>&1 | grep -v "^  running\|^machine\|USDT"
part 30 start $gpu --rows start 2>&1 | grep "^|\|^\["
part 90 default $gpu --rows default --subjects cat 2>&1 | grep "^|\|^\["
# what comes back: the log, each run's metrics.json and fit.log, not its checkpoints and arrays
find "$out" \( -name "*.ckpt" -o -name "*.npy" -o -name "*.ply" -o -name "events.out.*" \) -delete
