"""The pymunk backend's geometry (ebraille_sim.plant.pymunk.geometry): the parameters' checks,
the board mass, the contact strips and the step check of the stiffest explicit mode."""
from __future__ import annotations

import math

import numpy as np
import pytest

from ebraille_sim.physics.fingertip import tangent_stiffness_n_per_m
from ebraille_sim.physics.params import DeviceParams
from ebraille_sim.plant.pymunk.geometry import MechanismParams, check_mechanism_step, stiffest_mode_rad_s

def test_step_check_rejects_a_too_coarse_rate_with_one_line():
    with pytest.raises(ValueError, match="physics_rate_hz 200 is too low") as exc:
        check_mechanism_step(DeviceParams(), MechanismParams(physics_rate_hz=200.0))
    assert "\n" not in str(exc.value)
    assert check_mechanism_step(DeviceParams(), MechanismParams()) == pytest.approx(0.41, abs=0.01)
    with pytest.raises(ValueError, match="physics_rate_hz 1000 is too low"):
        check_mechanism_step(DeviceParams(), MechanismParams(physics_rate_hz=1000.0))

def test_parameters_are_checked_with_one_line_errors():
    for kw, msg in (({"n_contacts": 1}, "n_contacts"), ({"n_contacts": 2.5}, "n_contacts"),
                    ({"solver_iterations": 2.5}, "solver_iterations"),
                    ({"error_correction_per_step": 1.0}, "error_correction_per_step"),
                    ({"board_width_m": 0.03}, "must not exceed rod_spacing_m")):
        with pytest.raises(ValueError, match=msg) as exc:
            MechanismParams(**kw)
        assert "\n" not in str(exc.value)
    with pytest.raises(ValueError, match="weigh more than the moving mass"):
        MechanismParams(rack_mass_kg=3.5e-3).board_mass_kg(DeviceParams().drivetrain)

def test_board_mass_and_contact_strips():
    """The board carries the drive train's moving mass less the two racks; the strips split
    the contact width evenly about the press centre."""
    geo = MechanismParams()
    d = DeviceParams().drivetrain
    assert geo.board_mass_kg(d) == pytest.approx(d.moving_mass_kg - 2 * geo.rack_mass_kg)
    x = MechanismParams(n_contacts=4, contact_width_m=8e-3).contact_offsets_m()
    np.testing.assert_allclose(x, [-3e-3, -1e-3, 1e-3, 3e-3], atol=1e-15)

def test_stiffest_mode_of_a_centred_symmetric_press():
    """Two strips at +-x: the bounce mode (both racks together on the strips) has
    w^2 = k / (2 m_r + m_b) with k the strips' total tangent stiffness; the tilt mode is the
    other eigenvector.  The stiffest of the two is returned."""
    dev = DeviceParams()
    f = dev.finger
    geo = MechanismParams(n_contacts=2)
    k = tangent_stiffness_n_per_m(geo.max_regulated_force_n / f.relax_weight_inf, f.stiffness_b_n_per_m,
                                  f.exponent_m_per_m)
    mr, mb, s = geo.rack_mass_kg, geo.board_mass_kg(dev.drivetrain), geo.rod_spacing_m
    ib = mb * (geo.board_width_m ** 2 + geo.board_thickness_m ** 2) / 12.0
    bounce = math.sqrt(k / (2 * mr + mb))
    x = geo.contact_width_m / 4                      # the two strip centres are at +-w/4
    # tilt: racks opposite (yA = -yB = a): strip stiffness k/2 each at +-x, lever x / (s/2)
    k_tilt = k * (2 * x / s) ** 2                    # per unit of a, with both racks moving
    m_tilt = 2 * mr + 4 * ib / s ** 2
    tilt = math.sqrt(k_tilt / m_tilt)
    assert stiffest_mode_rad_s(dev, geo) == pytest.approx(max(bounce, tilt), rel=1e-9)
    assert check_mechanism_step(dev, geo) == pytest.approx(max(bounce, tilt) / geo.physics_rate_hz, rel=1e-9)
