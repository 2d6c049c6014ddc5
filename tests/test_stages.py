"""The light stages' protocol and runner (unps.lights.stages), and their verdicts."""

import numpy as np
import pytest

from unps.data.analytic import render_lambertian
from unps.data.lights import Lights, Verdict
from unps.errors import InputError
from unps.lights.contour import ContourAlignment
from unps.lights.reversal import ReversalTest
from unps.lights.selfcal import SelfCalibration
from unps.lights.stages import run_stages, select_stages

AVAILABLE = {"reversal": ReversalTest(), "contour": ContourAlignment(), "selfcal": SelfCalibration()}


class Nudge:
    """A stage that moves every light by a fixed turn about z, for the runner's tests."""

    name = "contour"

    def __call__(self, subject, lights):
        c, s = np.cos(np.radians(3)), np.sin(np.radians(3))
        turned = lights.directions @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]], np.float32).T
        return Lights(turned.astype(np.float32), lights.intensities, "nudged"), \
            Verdict("contour", "changed", "turned by 3°", {"rotation_deg": 3.0})


def test_stages_are_chosen_by_name_in_order():
    assert select_stages(["selfcal", "reversal"], AVAILABLE) == [AVAILABLE["selfcal"], AVAILABLE["reversal"]]
    assert select_stages([], AVAILABLE) == []


@pytest.mark.parametrize("names, message", [
    (["mirror"], "'mirror' is not a light stage; the stages are reversal, contour, selfcal"),
    (["reversal", "reversal"], "names 'reversal' twice"),
])
def test_unknown_or_repeated_stages_are_refused(names, message):
    with pytest.raises(InputError, match=message):
        select_stages(names, AVAILABLE)


def test_a_stage_without_its_settings_is_refused():
    with pytest.raises(InputError, match="light.selfcal is null"):
        select_stages(["selfcal"], {**AVAILABLE, "selfcal": None})
    with pytest.raises(InputError, match="light.reversal must hold the settings of the reversal stage"):
        select_stages(["reversal"], {**AVAILABLE, "reversal": "shadows"})


def test_the_runner_records_each_verdict_with_its_error_and_keeps_the_spread():
    subject = render_lambertian("sphere", size=24, n_lights=8, seed=2)
    start = Lights(subject.light_directions, subject.light_intensities, "estimated",
                   spread_deg=np.full(8, 1.5, np.float32),
                   verdicts=(Verdict("network", "changed", "a test"),))
    out = run_stages(subject, start, [Nudge()])
    assert [v.stage for v in out.verdicts] == ["network", "contour"]
    verdict = out.verdicts[-1]
    assert verdict.outcome == "changed" and verdict.evidence == {"rotation_deg": 3.0}
    assert 0.5 < verdict.errors["light_dir_mae"] < 3.01      # lights near the axis move less
    np.testing.assert_array_equal(out.spread_deg, start.spread_deg)
    record = verdict.to_dict()
    assert record["stage"] == "contour" and record["light_dir_mae"] == verdict.errors["light_dir_mae"]


def test_a_verdict_has_one_of_three_outcomes():
    with pytest.raises(ValueError, match="outcome"):
        Verdict("selfcal", "improved", "no such outcome")
