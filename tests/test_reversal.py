"""The convex/concave reversal test of estimated lights by their cast shadows (unps.lights.reversal)."""

import numpy as np
import pytest

from conftest import rendered
from unps.data.analytic import dome_lights
from unps.data.subject import Subject
from unps.errors import InputError
from unps.lights import Lights, with_lights
from unps.lights.reversal import HALF_TURN, ShadowEvidence, resolve_reversal, shadow_evidence
from unps.solvers.rpca import robust_init


def turned(subject: Subject) -> Lights:
    return Lights((subject.light_directions @ HALF_TURN).astype(np.float32), None, "estimated")


def evidence(subject: Subject, lights: Lights) -> ShadowEvidence:
    normals = robust_init(with_lights(subject, lights), lights.directions).normals
    return shadow_evidence(subject, lights, normals)


def test_the_bowl_casts_shadows_and_the_dome_nearly_none():
    bowl, dome = rendered(True), rendered(False)
    lit = np.einsum("hwc,nc->nhw", bowl.normals, bowl.light_directions) > 0.2
    assert (bowl.images[..., 0][lit & bowl.mask] == 0).mean() > 0.05
    lit = np.einsum("hwc,nc->nhw", dome.normals, dome.light_directions) > 0.2
    assert (dome.images[..., 0][lit & dome.mask] == 0).mean() < 0.01     # marching rounds at the rim


@pytest.mark.parametrize("concave", [True, False])
def test_lights_read_inside_out_are_turned_back_exactly(concave):
    subject = rendered(concave)
    found = evidence(subject, turned(subject))
    assert found.favours_reversal, found.describe()
    back, normals = resolve_reversal(subject, turned(subject))
    np.testing.assert_allclose(back.directions, subject.light_directions, atol=1e-6)
    right = robust_init(with_lights(subject, back), back.directions).normals
    np.testing.assert_allclose(normals, right, atol=1e-4)        # turned with the lights


@pytest.mark.parametrize("concave", [True, False])
def test_right_lights_are_kept(concave):
    subject = rendered(concave)
    right = Lights(subject.light_directions, None, "estimated")
    found = evidence(subject, right)
    assert not found.favours_reversal, found.describe()
    assert resolve_reversal(subject, right)[0] is right


def test_a_flat_subject_gives_no_evidence_and_keeps_its_lights():
    size, lights = 32, dome_lights(8, seed=1)
    mask = np.ones((size, size), bool)
    images = np.repeat(np.broadcast_to(0.5 * lights[:, 2, None, None], (8, size, size))[..., None], 3, -1)
    subject = Subject("plane", images.astype(np.float32), mask)
    estimate = Lights(lights, None, "estimated")
    found = evidence(subject, estimate)
    assert found.current_pairs == found.reversed_pairs == 0 and found.log_odds == 0
    assert resolve_reversal(subject, estimate)[0] is estimate


def test_estimate_lights_refuses_an_unknown_reversal_test():
    from unps.data.analytic import render_lambertian
    from unps.lightnet.estimate import estimate_lights
    with pytest.raises(InputError, match="light.reversal"):
        estimate_lights(render_lambertian(size=16, n_lights=4), reversal="mirror")
