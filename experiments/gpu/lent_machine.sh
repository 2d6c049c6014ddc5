#!/usr/bin/env bash
# One call on a lent GPU machine (a bare CUDA image without ../shared), about 8 minutes: the CUDA
# tests, the training loop's parts timed by hand (the loader pinned and not), the training and data
# rows, the paper preset and the default command, where a training process spends its time; every
# line also lands in $OUT/log.
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
timeout 120 python3 -m pytest -q -p no:cacheprovider tests/test_device.py tests/test_training_data.py \
  tests/test_geometry.py 2>&1 | tail -3
timeout 120 $gpu --rows loop --train-steps 30 2>&1 | grep "^|"
timeout 150 $gpu --rows train data 2>&1 | grep "^|"
timeout 200 $gpu --rows paper default --subjects cat 2>&1 | grep "^|"
timeout 60 $gpu --rows profile --train-steps 40 2>&1 | grep -A30 "Ordered by"
timeout 120 $gpu --rows paper --subjects pot1 2>&1 | grep "^|"
