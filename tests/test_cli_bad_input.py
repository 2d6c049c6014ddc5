"""Every bad-input case of experiments/bad_input/cases.py through the real command line."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments" / "bad_input"))
from cases import CASES, run  # noqa: E402

pytestmark = pytest.mark.slow   # 53 command lines, ~6 min


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_bad_input_exits_cleanly_and_names_the_culprit(case):
    outcome = run(case)
    assert not outcome.traceback, outcome.message
    assert outcome.code == case.code, outcome.message
    assert case.culprit in outcome.message
    assert outcome.wrote_metrics == (case.code == 0)   # an error leaves no metrics.json
    assert not outcome.left_run_folder                  # nor a run folder
