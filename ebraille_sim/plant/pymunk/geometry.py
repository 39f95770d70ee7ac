"""Geometry of the 2-D mechanism and the step it can take.

:class:`MechanismParams` holds what the lumped model has no use for (rod spacing, rack and
board sizes, the tooth offset, the rod friction, the contact strips, the pymunk step and
solver options); masses and forces of the drive train come from
:class:`~ebraille_sim.physics.params.DriveTrainParams`.

Step size
---------
Chipmunk's joints are solved implicitly; springs and body forces are explicit.  The
mesh spring is made linearly implicit (:mod:`ebraille_sim.plant.pymunk.model`).  The pulp
springs stay explicit: :func:`check_mechanism_step` computes the stiffest mode of the
racks and board on the pulp (mesh in its gap, fully relaxed 3 N contact, w = 2049 rad/s
with the pulp's c0 = 0.15) and rejects ``w h > 1``.  The default 5 kHz (a whole multiple
of the 1 kHz control rate) gives ``w h = 0.41``; the modes the force loop sees (the pulp
against the reflected inertia) have ``w h`` near 0.01.  ``physics_rate_hz = 10000`` runs
the mechanism at the lumped plant's own step.

Examples
--------
>>> from ebraille_sim.physics.params import DeviceParams
>>> round(check_mechanism_step(DeviceParams(), MechanismParams()), 2)
0.41
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ebraille_sim.base.fields import sourced
from ebraille_sim.physics.fingertip import tangent_stiffness_n_per_m
from ebraille_sim.physics.params import TACTILE_FORCE_MAX_N, DeviceParams, check_finite

__all__ = ["MechanismParams", "MAX_STEP_WH", "stiffest_mode_rad_s", "check_mechanism_step"]

MAX_STEP_WH = 1.0
"""Largest ``w h`` accepted for the stiffest explicit mode (symplectic Euler: stable below 2,
accurate below 1; the criterion of :func:`ebraille_sim.plant.lumped.check_step`)."""


@dataclass(frozen=True)
class MechanismParams:
    """Geometry of the 2-D mechanism and options of the pymunk model.

    Masses and forces of the drive train (gear ratio, backlash, mesh stiffness, guide
    friction, travel) come from :class:`~ebraille_sim.physics.params.DriveTrainParams`; only what
    the lumped model has no use for is here.
    """
    rod_spacing_m: float = sourced(
        21e-3, "m", "[D] board width 19.3 mm plus the 1.7 mm of a rack beside each edge [E]", positive=True)
    board_width_m: float = sourced(
        19.3e-3, "m", "[D] FSR 402 overall diameter 18.28 mm [R datasheet] plus 0.5 mm margin each side [E]",
        positive=True)
    board_thickness_m: float = sourced(1.6e-3, "m", "[E] standard FR4 board", positive=True)
    rack_mass_kg: float = sourced(
        2.0e-3, "kg", "[E] a third of the 6 g moving mass each (rack with its bore and pin); the board, "
        "display and FSR get the rest", positive=True)
    rack_length_m: float = sourced(14e-3, "m", "[E] 6 mm travel plus 8 mm of engaged bore", positive=True)
    rack_width_m: float = sourced(3e-3, "m", "[E] bore for a 2 mm rod plus the teeth", positive=True)
    bushing_length_m: float = sourced(
        8e-3, "m", "[E] distance between the two ends of the rack's bore on the rod", positive=True)
    mesh_offset_m: float = sourced(
        2.0e-3, "m", "[E] tooth pitch line to rod axis: 1 mm rod radius + 0.5 mm wall + 0.5 mm tooth",
        nonneg=True)
    rod_friction_coefficient: float = sourced(
        0.2, "-", "[R] POM on steel, dry, mu_k = 0.20-0.22 (Stagnoli); the static level uses the "
        "drive train's guide_breakaway_ratio (0.25/0.2)", nonneg=True)
    contact_width_m: float = sourced(
        8e-3, "m", "[D] Hertz contact diameter 2 (3 F R / 4 E*)^(1/3) of a pad R = 8 mm [E], E = 0.1 MPa [R], "
        "nu = 0.5: 7.1 mm at 1 N, 9.0 mm at 2 N", positive=True)
    n_contacts: int = sourced(3, "-", "[E] contact strips across the width (2 or more)", positive=True)
    physics_rate_hz: float = sourced(
        5000.0, "Hz", "[D] w h = 0.41 for the stiffest explicit mode (pulp on the free board), 0.01 for the "
        "modes of the force loop (see check_mechanism_step)", positive=True)
    solver_iterations: int = sourced(10, "-", "[E] Chipmunk's default", positive=True)
    error_correction_per_step: float = sourced(
        0.2, "-", "[E] fraction of a joint's position error removed per step (Chipmunk's default, "
        "10 % per 1/60 s, would take 0.16 s at 2 kHz)", positive=True)
    fsr_area_model: bool = sourced(True, "-", "[E] strips conduct in parallel: G ~ sum a_j^(1-n) F_j^n")
    max_regulated_force_n: float = sourced(
        TACTILE_FORCE_MAX_N, "N", "[R] seed paper: the device regulates 0.2-3 N; used by the step check",
        positive=True)

    def __post_init__(self):
        check_finite(self)
        if int(self.n_contacts) != self.n_contacts or self.n_contacts < 2:
            raise ValueError(f"MechanismParams.n_contacts must be a whole number >= 2, got {self.n_contacts}")
        if int(self.solver_iterations) != self.solver_iterations:
            raise ValueError(f"MechanismParams.solver_iterations must be a whole number, got {self.solver_iterations}")
        if not self.error_correction_per_step < 1.0:
            raise ValueError(f"MechanismParams.error_correction_per_step must be in (0, 1), "
                             f"got {self.error_correction_per_step}")
        if self.board_width_m > self.rod_spacing_m:
            raise ValueError(f"MechanismParams.board_width_m ({self.board_width_m:g}) must not exceed "
                             f"rod_spacing_m ({self.rod_spacing_m:g})")

    def board_mass_kg(self, drivetrain) -> float:
        """Board + display + FSR: the drive train's moving mass less the two racks, kg."""
        m = drivetrain.moving_mass_kg - 2.0 * self.rack_mass_kg
        if not m > 0:
            raise ValueError(f"two racks of {self.rack_mass_kg:g} kg weigh more than the moving mass "
                             f"{drivetrain.moving_mass_kg:g} kg of the drive train")
        return m

    def contact_offsets_m(self) -> np.ndarray:
        """Centres of the contact strips relative to the press centre, m, shape (n_contacts,)."""
        n = int(self.n_contacts)
        w = self.contact_width_m
        return (np.arange(n) + 0.5) * (w / n) - 0.5 * w


def stiffest_mode_rad_s(device: DeviceParams, mech: MechanismParams) -> float:
    """Largest angular frequency (rad/s) of the racks + board on the meshes and the pulp.

    Coordinates: the two rack heights, the pinion held (its reflected inertia is 500 times
    the moving mass).  The board follows the racks (pin and slot): centre ``(yA + yB)/2``,
    tilt ``(yB - yA)/s``.  Each mesh has half the mesh stiffness; each contact strip the
    tangent stiffness ``(b + m Fe)/n`` at the elastic force ``Fe = F_max / c0`` of a fully
    relaxed contact at ``max_regulated_force_n``.
    """
    d, f = device.drivetrain, device.finger
    s = mech.rod_spacing_m
    mr = mech.rack_mass_kg
    mb = mech.board_mass_kg(d)
    ib = mb * (mech.board_width_m ** 2 + mech.board_thickness_m ** 2) / 12.0
    mass = mr * np.eye(2) + mb / 4.0 * np.ones((2, 2)) + ib / s ** 2 * np.array([[1.0, -1.0], [-1.0, 1.0]])
    k_tan = tangent_stiffness_n_per_m(mech.max_regulated_force_n / f.relax_weight_inf,
                                      f.stiffness_b_n_per_m, f.exponent_m_per_m)
    stiff = np.zeros((2, 2))
    n = int(mech.n_contacts)
    for x in mech.contact_offsets_m():
        a = np.array([0.5 - x / s, 0.5 + x / s])
        stiff += k_tan / n * np.outer(a, a)
    lam = np.linalg.eigvals(np.linalg.solve(mass, stiff)).real
    return float(math.sqrt(max(lam.max(), 0.0)))


def check_mechanism_step(device: DeviceParams, mech: MechanismParams) -> float:
    """``w h`` of the stiffest explicit mode of the mechanism; raise if above :data:`MAX_STEP_WH`."""
    w = stiffest_mode_rad_s(device, mech)
    wh = w / mech.physics_rate_hz
    if wh > MAX_STEP_WH:
        need = w / MAX_STEP_WH
        raise ValueError(f"mechanism physics_rate_hz {mech.physics_rate_hz:g} is too low for its stiffest "
                         f"mode (w = {w:.0f} rad/s, w h = {wh:.2f} > {MAX_STEP_WH}); use at least {need:.0f} Hz "
                         f"(a whole divisor of the device physics rate)")
    return wh
