"""The [mechanism] scenario section (ebraille_sim.scenarios.mechanism_section): strict
validation and the pose inputs it builds."""
from __future__ import annotations

import math

import numpy as np
import pytest

from ebraille_sim.physics.params import STANDARD_GRAVITY_M_PER_S2, DeviceParams
from ebraille_sim.scenarios.mechanism_section import build_inputs, validate_section
from ebraille_sim.scenarios.spec import ScenarioError

def test_scenario_section_is_validated_strictly():
    with pytest.raises(ScenarioError, match="unknown key 'offset' in \\[mechanism\\]; allowed: "):
        validate_section("x.toml", {"offset": 1.0})
    with pytest.raises(ScenarioError, match="press_offset_m = 0.1 is out of range"):
        validate_section("x.toml", {"press_offset_m": 0.1})
    with pytest.raises(ScenarioError, match="times must increase"):
        validate_section("x.toml", {"pose_steps": [[2.0, 0.0, 0.0], [1.0, 0.0, 0.0]]})
    sec = validate_section("x.toml", {"pose_steps": [[1.0, 0.004, 2.0]], "hand_roll_deg": 90.0})
    t = np.arange(0.0, 2.0, 0.5)
    inp = build_inputs(sec, t, None, DeviceParams())
    assert list(inp["press_offset_m"][1]) == [0.0, 0.0, 0.004, 0.004]
    assert inp["finger_tilt_rad"][1][-1] == pytest.approx(math.radians(2.0))
    assert inp["gravity_lateral_m_per_s2"][1][0] == pytest.approx(-STANDARD_GRAVITY_M_PER_S2)
