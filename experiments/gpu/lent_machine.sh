#!/usr/bin/env bash
# One call on a lent GPU machine (a bare CUDA image without ../shared), about 9 minutes: the CUDA
# tests, where a short training run's process spends its time, then every row of run.py.
#   here:   bash ../shared/tools/gpu-prep.sh          (packs .gpu/: wheels and two DiLiGenT crops)
#   there:  bash experiments/gpu/lent_machine.sh       (with .gpu/ carried along; writes under $OUT)
set -u
out=${OUT:-runs/gpu}
python3 -m pip install -q --no-index --no-deps --target /tmp/site .gpu/whl/*.whl
export PYTHONPATH=/tmp/site:$PWD
mkdir -p .gpu/diligent && ln -sfn "$PWD/.gpu/data" .gpu/diligent/pmsData_crop
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader
timeout 120 python3 -m pytest -q -p no:cacheprovider tests/test_device.py tests/test_training_data.py \
  tests/test_geometry.py 2>&1 | tail -3
timeout 120 python3 experiments/gpu/run.py --rows profile --train-steps 40 --out "$out" 2>&1 | grep -v "^  running"
timeout 180 python3 experiments/gpu/run.py --rows train data --out "$out" 2>&1 | grep "^|"
timeout 300 python3 experiments/gpu/run.py --rows paper default --diligent .gpu/diligent --out "$out" 2>&1 | grep "^|"
