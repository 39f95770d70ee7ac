"""The benchmark's ``hysteresis_bound``: the true force as the FSR's hysteresis lets a firmware know it."""
import dataclasses
import math

import numpy as np
import pytest

from controllers.bounds import HysteresisSeen, make_hysteresis_bound
from ebraille_sim.physics import fsr as fsr_law
from ebraille_sim.physics.fsr import play_widths
from ebraille_sim.physics.params import DeviceParams, FSRParams


def _seen(fsr, forces, start=1.0):
    c = make_hysteresis_bound(fsr)
    c.reset(force_est_n=start, setpoint_n=start)
    return np.array([c.seen_force_n(f) for f in forces])


def test_pressing_on_from_the_start_is_seen_exactly():
    """The operators start on their loading branch (as after a press to the starting force)."""
    f = np.linspace(1.0, 2.0, 101)
    assert np.max(np.abs(_seen(FSRParams(), f) - f)) < 1e-9


@pytest.mark.parametrize("h", [0.05, 0.10, 0.15])
def test_blind_stretch_after_a_reversal_is_twice_the_smallest_play(h):
    """After a reversal at 1.5 N the force seen holds until the true force has moved by
    ``1 - exp(-2 w1)`` (w1 the smallest play width, ln N), then is exact again."""
    fsr = dataclasses.replace(FSRParams(), hysteresis_fraction=h)
    w1 = play_widths(fsr)[0][0]
    blind = 1.0 - math.exp(-2.0 * w1)
    up = np.linspace(1.0, 1.5, 51)
    down = 1.5 * (1.0 - np.linspace(0.0, 2.0 * blind, 201)[1:])
    seen = _seen(fsr, np.concatenate([up, down]))[len(up):]
    moved = (1.5 - down) / (1.5 * blind)
    assert np.all(seen[moved < 1 - 1e-6] == pytest.approx(1.5, abs=1e-12))
    assert np.max(np.abs(seen[moved > 1 + 1e-6] - down[moved > 1 + 1e-6])) < 1e-9
    # the stretch grows with the film's rate-independent loop (nominal 7.1 % of the datasheet's
    # 10 %: 3.3 % of the force)
    h_play = fsr_law.play_loop_fraction(fsr)
    assert 0.3 * h_play < blind < 0.6 * h_play


def test_the_wrapper_feeds_the_seen_force_to_its_inner_controller():
    class Echo:
        name = "echo"
        config = None

        def reset(self, *, force_est_n, setpoint_n, command_v=0.0):
            self.got = []

        def update(self, force_est_n, setpoint_n, dt_s, motor_current_a=None):
            self.got.append(force_est_n)
            return 0.0

    c = HysteresisSeen(Echo(), FSRParams())
    assert c.feedback == "true_force" and c.compiled() is None
    c.reset(force_est_n=1.2, setpoint_n=1.0)
    for f in (1.2, 1.19, 1.18):
        c.update(f, 1.0, 1e-3)
    assert c.inner.got == [1.2, 1.2, 1.2]
    with pytest.raises(TypeError, match="Controller protocol"):
        HysteresisSeen(object(), FSRParams())


def test_no_hysteresis_film_sees_everything():
    f = 1.0 + 0.2 * np.sin(np.linspace(0.0, 20.0, 400))
    fsr = dataclasses.replace(DeviceParams().fsr, hysteresis_fraction=0.0)
    assert np.max(np.abs(_seen(fsr, f) - f)) < 1e-9
