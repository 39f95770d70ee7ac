"""The device as a 2-D pymunk mechanism behind the :class:`~ebraille_sim.plant.loop.Plant` interface.

The lumped plant (:mod:`ebraille_sim.plant.kernel`) moves the drive train and the board as one
body on a line.  Here the same device is a planar linkage in the cross-section of the
finger (``x`` across the finger, ``y`` along the board travel, toward the pulp)::

            finger (kinematic body: gap, tilt, lateral offset of the press)
        ~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~
          |        |        |     contact springs (exponential + QLV law, per strip)
     o====[========board + 3x2 display + FSR========]=o      pin (rack A)  /  pin in slot (rack B)
     ||                                                ||
    [||]  rack A on its rod        pinion     rack B  [||]   two bushing points per rack
    [||]<-- mesh (backlash) --> ( shaft ) <-- mesh -->[||]   (GrooveJoints on the rods)
     ||                                                ||
    ============================ device frame ===================  (static body)

Bodies and constraints
----------------------
* **frame**: the static body, strapped to the finger.
* **racks** (one per guide rod, ``rod_spacing_m`` apart): each slides on its rod through a
  bore whose two ends are GrooveJoints to the frame, ``bushing_length_m`` apart.  The rods
  carry the racks' side loads; the groove impulses give them at every step.
* **board** (with the display and the FSR): carried by a PivotJoint on rack A and a pin in
  a slot (GrooveJoint along the board) on rack B, so that it tilts when the racks move
  unequally without over-constraining the rods.
* **pinion**: one shaft with a pinion meshing each rack.  Its body carries the motor's
  reflected inertia ``J (N/r)^2`` and moves along the rack line (its coordinate is the
  pinion pitch-point position, as in the lumped model); it is drawn rotating by ``y / r``.
* **mesh** with each rack: the lumped law :func:`~ebraille_sim.physics.drivetrain.mesh_force`
  (backlash dead zone, then a stiff contact that can only push) with half the mesh
  stiffness and damping per rack, so that the two meshes in parallel are the lumped one.
  The spring part is applied as a force on the rack's tooth line, ``mesh_offset_m`` inboard
  of the rod axis (its moment on the rack is carried by the two bushings as side loads);
  the damping part is a DampedSpring between the pinion and the rack, switched on while
  the teeth are in contact and solved implicitly by Chipmunk.
* **motor**: the armature current is advanced by :func:`ebraille_sim.physics.motor.current_step`
  with the pinion speed; the force ``kM i N/r`` drives the pinion body.
* **friction**: Stribeck (:func:`ebraille_sim.physics.drivetrain.stribeck`) on the pinion (brush
  and bearing friction plus the load-dependent gear loss ``mu |F_mesh|``, as in the
  lumped kernel) and on each rack (half the guide preload friction plus
  ``mu_rod (|N_top| + |N_bottom|)`` from the bushing side loads: a rack binds when the
  load shifts to it).  Dry friction is a velocity constraint (a PinJoint with no position
  correction) whose ``max_force`` is the friction level: it holds a body at rest below the
  break-away force, like the velocity-level friction of the lumped kernel.  Viscous
  friction is an explicit force.
* **end stops**: after every step the lumped law :func:`~ebraille_sim.physics.drivetrain.end_stop`
  clips each rack and the board to ``[travel_min_m, travel_max_m]`` and removes their
  velocity into the stop (inelastic).  A SlideJoint in the solver instead lets a rack
  driven at the stall current rattle at the stop (its position correction and
  warm-started impulse against the explicit mesh force: 64 um past the stop at 5 kHz).
* **pulp**: ``n_contacts`` DampedSprings between the board and the finger body, each on an
  equal strip of the contact width; its ``force_func`` applies the exponential law and the
  Prony (QLV) relaxation of :mod:`ebraille_sim.physics.fingertip`, scaled by the strip's share of
  the contact area, to the local compression ``d = rest_length - dist`` (the signed
  Chipmunk convention: positive pushes the anchors apart).  A strip beyond the board edge
  does not touch the board.
* **gravity**: ``Space.gravity = (gravity_lateral, gravity_along)`` acts on the racks and
  the board; the pinion body's reflected inertia is not a weight, so it is compensated.

The sensor
----------
The FSR under the display sees the contact force of every strip.  With
``fsr_area_model`` each strip loads its share ``a_j`` of the sensor area and the strips
conduct in parallel, ``G ~ sum a_j^(1-n) F_j^n`` (uniform pressure gives back ``F^n``), so an
uneven press reads lower than the same force spread evenly [E]: Interlink notes that the
response depends on pressure and contact area, not only force.  The equivalent uniform
force ``(sum a_j^(1-n) F_j^n)^(1/n)`` of every pymunk step drives the sensor chain of the
lumped model (:func:`ebraille_sim.plant.kernel.advance_sensor_only`: FSR lag, hysteresis, creep,
divider, noise, ADC, anti-alias filter, estimator) over the device physics steps that the
pymunk step spans, once per control period; the ``contact_force_n`` slot then holds the
true total force.

Step size
---------
Chipmunk's joints are solved implicitly; springs and body forces are explicit.  The
mesh spring is made linearly implicit: while the teeth touch, its damping is ``c + k h``,
and the spring force from the old position plus an implicit damper ``k h`` is the
backward-Euler step ``F = k x_new``, stable at any step (its extra damping acts on the
parasitic ~400 Hz mesh mode only).  The pulp springs stay explicit:
:func:`check_mechanism_step` computes the stiffest mode of the racks and board on the
pulp (mesh in its gap, fully relaxed 3 N contact, w = 2049 rad/s with the pulp's
c0 = 0.15) and rejects ``w h > 1``.  The default 5 kHz (a whole multiple of the 1 kHz
control rate) gives ``w h = 0.41``; the modes the force loop sees (the pulp against the
reflected inertia) have ``w h`` near 0.01.  ``physics_rate_hz =
10000`` runs the mechanism at the lumped plant's own step.

Examples
--------
>>> from ebraille_sim.physics.params import DeviceParams
>>> plant = PymunkPlant.from_devices([DeviceParams()], seeds=[1])
>>> plant.set_finger(1.0e-3)
>>> for _ in range(300):
...     plant.advance(3.0)
>>> bool(plant.contact_force_n[0] > 0.0)
True
"""
from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass

import numpy as np
import pymunk
from ebraille_sim.base.compiled import njit
from ebraille_sim.base.fields import sourced
from ebraille_sim.physics.drivetrain import end_stop, mesh_force, stribeck
from ebraille_sim.physics.fingertip import (contact_force, elastic_force, prony_coefficients, prony_step,
                                            tangent_stiffness_n_per_m)
from ebraille_sim.physics.motor import current_decay, current_step
from ebraille_sim.physics.params import TACTILE_FORCE_MAX_N, DeviceParams, check_finite, replace_checked
from ebraille_sim.plant import kernel
from ebraille_sim.plant.layout import P, S, U
from ebraille_sim.plant.loop import Plant, pack_devices

__all__ = ["MechanismParams", "PymunkPlant", "check_mechanism_step", "stiffest_mode_rad_s", "mesh_flank",
           "draw_snapshot", "draw_mechanism", "recording", "write_animation"]

# scalar laws, called from Python on the pymunk path (the same code the kernel compiles);
# the mesh law (drivetrain.mesh_force) picks the loaded flank (mesh_flank) and is set into
# the mesh DampedSprings by _Mechanism._mesh_state
_stribeck = stribeck.py_func
_elastic = elastic_force.py_func
_prony_step = prony_step.py_func
_contact_force = contact_force.py_func
_current_step = current_step.py_func
_mesh_force = mesh_force.py_func
_end_stop = end_stop.py_func

V_MAX = 10.0
"""Speed (m/s) of the pinion beyond which a run is reported as diverged (no-load speed: 0.06 m/s)."""

MAX_STEP_WH = 1.0
"""Largest ``w h`` accepted for the stiffest explicit mode (symplectic Euler: stable below 2,
accurate below 1; the criterion of :func:`ebraille_sim.plant.loop.check_step`)."""


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


# --------------------------------------------------------------------------------------
# one device
# --------------------------------------------------------------------------------------

_cp = pymunk.cp


def mesh_flank(dx_m: float, half_gap_m: float) -> int:
    """Loaded tooth flank of the mesh law at ``dx = x_pinion - x_rack``: +1 upper, -1 lower, 0 in the gap.

    The sign of :func:`~ebraille_sim.physics.drivetrain.mesh_force` with unit stiffness and
    no damping, i.e. the dead zone of the lumped law.
    """
    f = _mesh_force(dx_m, 0.0, half_gap_m, 1.0, 0.0)
    return 1 if f > 0.0 else (-1 if f < 0.0 else 0)


@njit(cache=True)
def _sensor_sequence(s, p, u, forces_n, n_sub):
    """The lumped sensor chain over consecutive pymunk steps, each spanning ``n_sub`` physics steps.

    ``forces_n[k]`` is the force that loads the FSR during pymunk step ``k``; the
    ``contact_force_n`` slot is left at the last of them.  The firmware then reads the motor
    current once (:func:`ebraille_sim.plant.kernel.current_sample`), as at the end of every
    control period of the lumped plant.
    """
    for k in range(forces_n.shape[0]):
        kernel.advance_sensor_only(s, p, u, forces_n[k], n_sub)
    if forces_n.shape[0] > 0:
        kernel.current_sample(s, p)


class _Mechanism:
    """The pymunk space of one device and the per-step physics outside Chipmunk."""

    L_REF = 10e-3       # anchor separation of the mesh and contact constraints, m
    L_FAR = 1.0         # distance to the frame anchor of the friction constraints, m

    def __init__(self, device: DeviceParams, mech: MechanismParams, p: np.ndarray, board_pos_m: float):
        d, m, fing = device.drivetrain, device.motor, device.finger
        self.device, self.mech = device, mech
        h = 1.0 / mech.physics_rate_hz
        ratio = device.rates.physics_rate_hz / mech.physics_rate_hz
        if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
            raise ValueError(f"the device physics rate ({device.rates.physics_rate_hz:g} Hz) must be a whole "
                             f"multiple of the mechanism physics rate ({mech.physics_rate_hz:g} Hz)")
        ratio_c = mech.physics_rate_hz / device.rates.control_rate_hz
        if abs(ratio_c - round(ratio_c)) > 1e-9 or round(ratio_c) < 1:
            raise ValueError(f"the mechanism physics rate ({mech.physics_rate_hz:g} Hz) must be a whole "
                             f"multiple of the control rate ({device.rates.control_rate_hz:g} Hz)")
        check_mechanism_step(device, mech)
        self.h = h
        self.sensor_sub = int(round(ratio))
        self.steps_per_control = int(round(ratio_c))
        self.f_sensor = np.zeros(self.steps_per_control)

        # motor and pinion side, at the rack line (the packed values of the lumped kernel)
        g = p[P.n_over_r_per_m]
        decay = current_decay(h, m.resistance_ohm, m.inductance_h)
        self.m_pinion = p[P.pinion_mass_kg]
        self.half_gap = p[P.half_backlash_m]
        self.k_mesh = 0.5 * p[P.mesh_k_n_per_m]
        self.c_mesh = 0.5 * p[P.mesh_c_n_s_per_m]
        # finger (QLV)
        self.fb, self.fm = fing.stiffness_b_n_per_m, fing.exponent_m_per_m
        self.c0 = fing.relax_weight_inf
        cw = (fing.relax_weight_1, fing.relax_weight_2, fing.relax_weight_3)
        a, beta = prony_coefficients(h, (fing.relax_tau_1_s, fing.relax_tau_2_s, fing.relax_tau_3_s))
        self.pa = tuple(a)
        self.pc = cw
        self.pbeta = tuple(beta)

        s_half = 0.5 * mech.rod_spacing_m
        self.rod_x = (-s_half, s_half)
        space = pymunk.Space()
        space.iterations = int(mech.solver_iterations)
        space.gravity = (0.0, -device.gravity_m_per_s2)
        self.space = space
        frame = space.static_body
        xb = float(board_pos_m)

        # pinion (reflected inertia) moving along the rack line, held on its axis by a groove
        pin = pymunk.Body(self.m_pinion, math.inf)
        pin.position = (0.0, xb)
        space.add(pin)
        space.add(pymunk.GrooveJoint(frame, pin, (0.0, xb - 1.0), (0.0, xb + 1.0), (0.0, 0.0)))
        pin_fric = pymunk.PinJoint(frame, pin, (0.0, xb - self.L_FAR), (0.0, 0.0))
        pin_fric.max_bias = 0.0
        pin_fric.max_force = p[P.pinion_static_n]
        space.add(pin_fric)
        if p[P.pinion_viscous_n_s_per_m] > 0.0:
            space.add(pymunk.DampedSpring(frame, pin, (0.0, xb - self.L_FAR), (0.0, 0.0), self.L_FAR, 0.0,
                                          p[P.pinion_viscous_n_s_per_m]))
        self.pinion, self.pin_fric = pin, pin_fric

        # racks on their rods
        mr = mech.rack_mass_kg
        lr, wr = mech.rack_length_m, mech.rack_width_m
        moment_r = mr * (lr * lr + wr * wr) / 12.0
        self.racks, self.rack_fric, self.bushings, self.dampers = [], [], [], []
        self.bush_y = (-1e-3, -1e-3 - mech.bushing_length_m)
        for x in self.rod_x:
            inward = 1.0 if x < 0 else -1.0
            rack = pymunk.Body(mr, moment_r)
            rack.center_of_gravity = (0.0, -0.5 * lr)
            rack.position = (x, xb)
            space.add(rack)
            bushes = []
            for yb in self.bush_y:
                gj = pymunk.GrooveJoint(frame, rack, (x, xb - 1.0), (x, xb + 1.0), (0.0, yb))
                space.add(gj)
                bushes.append(gj)
            fr = pymunk.PinJoint(frame, rack, (x, xb - self.L_FAR), (0.0, 0.0))
            fr.max_bias = 0.0
            fr.max_force = 0.5 * p[P.guide_static_n]
            space.add(fr)
            if p[P.guide_viscous_n_s_per_m] > 0.0:
                space.add(pymunk.DampedSpring(frame, rack, (x, xb - self.L_FAR), (0.0, 0.0), self.L_FAR, 0.0,
                                              0.5 * p[P.guide_viscous_n_s_per_m]))
            tooth_x = inward * mech.mesh_offset_m
            damper = pymunk.DampedSpring(pin, rack, (x + tooth_x, -self.L_REF), (tooth_x, 0.0), self.L_REF, 0.0, 0.0)
            space.add(damper)
            self.racks.append(rack)
            self.rack_fric.append(fr)
            self.bushings.append(bushes)
            self.dampers.append(damper)

        # board: pin on rack A, pin in a slot on rack B
        mb = mech.board_mass_kg(d)
        wb, tb = mech.board_width_m, mech.board_thickness_m
        board = pymunk.Body(mb, mb * (wb * wb + tb * tb) / 12.0)
        board.center_of_gravity = (0.0, -0.5 * tb)
        board.position = (0.0, xb)
        space.add(board)
        space.add(pymunk.PivotJoint(self.racks[0], board, (0.0, 0.0), (-s_half, 0.0)))
        space.add(pymunk.GrooveJoint(board, self.racks[1], (s_half - 0.5e-3, 0.0), (s_half + 0.5e-3, 0.0),
                                     (0.0, 0.0)))
        self.board = board

        # finger: kinematic body at the press centre on the undeformed pulp surface
        finger = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
        space.add(finger)
        self.finger = finger
        n = int(mech.n_contacts)
        self.xi = [float(v) for v in mech.contact_offsets_m()]
        self.share = 1.0 / n
        self.fe = [0.0] * n
        self.h1, self.h2, self.h3 = [0.0] * n, [0.0] * n, [0.0] * n
        self.fc = [0.0] * n
        self.active = [True] * n
        self.springs = []
        for j in range(n):
            sp = pymunk.DampedSpring(board, finger, (self.xi[j], 0.0), (self.xi[j], self.L_REF),
                                     self.L_REF, 0.0, 0.0)
            sp.force_func = self._pulp_spring(j)
            space.add(sp)
            self.springs.append(sp)

        bias = (1.0 - mech.error_correction_per_step) ** (1.0 / h)
        for c in space.constraints:
            c.error_bias = bias
        space.step(0.0)           # pymunk's one-off body checks; Chipmunk skips a zero step
        self.pose = None
        self.gravity = None
        self.current_a = 0.0
        self.engaged = [0, 0]
        self.mesh_force_n = [0.0, 0.0]
        self.rack_friction_n = [0.0, 0.0]
        self.rack_friction_limit_n = [0.0, 0.0]
        self.side_load_n = [0.0, 0.0]
        # constants of the step loop
        self._const = (
            h, 1.0 / h, self.steps_per_control, self.sensor_sub, self.m_pinion, g,
            p[P.motor_r_ohm], p[P.motor_ke], p[P.motor_kt], decay,
            p[P.pinion_coulomb_n], p[P.pinion_static_n], p[P.gear_mu],
            p[P.stribeck_v_m_per_s], self.half_gap, self.k_mesh,
            0.5 * p[P.guide_coulomb_n], d.guide_breakaway_ratio, mech.rod_friction_coefficient,
            pin._body, pin_fric._constraint, self.racks[0]._body, self.racks[1]._body,
            self.rack_fric[0]._constraint, self.rack_fric[1]._constraint,
            self.bushings[0][0]._constraint, self.bushings[0][1]._constraint,
            self.bushings[1][0]._constraint, self.bushings[1][1]._constraint,
            self.dampers[0]._constraint, self.dampers[1]._constraint, space._space,
            mech.fsr_area_model, device.fsr.exponent, self.share ** (1.0 - device.fsr.exponent),
            (self.racks[0]._body, self.racks[1]._body, board._body), d.travel_min_m, d.travel_max_m,
        )

    # --- force functions --------------------------------------------------------------
    def _pulp_spring(self, j: int):
        """force_func of contact strip ``j``: its share of the QLV law at ``d = rest - dist``."""
        fb, fm, c0 = self.fb, self.fm, self.c0
        a1, a2, a3 = self.pa
        c1, c2, c3 = self.pc
        b1, b2, b3 = self.pbeta
        share = self.share
        fe, h1, h2, h3, fc, active = self.fe, self.h1, self.h2, self.h3, self.fc, self.active
        elastic, step, contact = _elastic, _prony_step, _contact_force
        rest = self.L_REF

        def force(spring, dist):
            d = rest - dist
            fe_new = share * elastic(d, fb, fm) if active[j] else 0.0
            dfe = fe_new - fe[j]
            fe[j] = fe_new
            x1 = step(h1[j], a1, c1, b1, dfe)
            x2 = step(h2[j], a2, c2, b2, dfe)
            x3 = step(h3[j], a3, c3, b3, dfe)
            h1[j], h2[j], h3[j] = x1, x2, x3
            f = contact(d, fe_new, c0, x1, x2, x3) if active[j] else 0.0
            fc[j] = f
            return f
        return force

    def _mesh_state(self, dmp, side: int) -> None:
        """Set a mesh spring for tooth contact on the upper (+1) or lower (-1) flank, or none (0).

        In contact the DampedSpring's own linear force ``k (rest - dist)`` with
        ``rest = L_REF - side * b`` is the lumped law ``k (dx - side * b)``, and its damping
        ``c + k h`` is the mesh damping plus the term that makes the spring's explicit step
        backward Euler (``F = k x_new``), which is stable for any step.
        """
        c = _cp
        if side == 0:
            c.cpDampedSpringSetStiffness(dmp, 0.0)
            c.cpDampedSpringSetDamping(dmp, 0.0)
        else:
            c.cpDampedSpringSetRestLength(dmp, self.L_REF - side * self.half_gap)
            c.cpDampedSpringSetStiffness(dmp, self.k_mesh)
            c.cpDampedSpringSetDamping(dmp, self.c_mesh + self.k_mesh * self.h)

    # --- inputs -----------------------------------------------------------------------
    def apply_inputs(self, u: np.ndarray) -> None:
        """Finger pose and gravity from the input vector (only when they change)."""
        pose = (u[U.finger_pos_m], u[U.press_offset_m], u[U.finger_tilt_rad])
        if pose != self.pose:
            y_f, x_c, tilt = (float(v) for v in pose)
            if not all(math.isfinite(v) for v in (y_f, x_c, tilt)) or abs(tilt) >= 0.5 * math.pi:
                raise ValueError(f"finger pose must be finite with |tilt| < 90 deg, got "
                                 f"position {y_f}, offset {x_c}, tilt {tilt}")
            self.finger.position = (x_c, y_f)
            half_w = 0.5 * self.mech.board_width_m
            tan_t = math.tan(tilt)
            for j, sp in enumerate(self.springs):
                xj = x_c + self.xi[j]
                sp.anchor_a = (xj, 0.0)
                sp.anchor_b = (self.xi[j], self.L_REF + self.xi[j] * tan_t)
                self.active[j] = abs(xj) <= half_w
            self.pose = pose
        grav = (u[U.gravity_lateral_m_per_s2], u[U.gravity_along_m_per_s2])
        if grav != self.gravity:
            gx, gy = float(grav[0]), float(grav[1])
            if not (math.isfinite(gx) and math.isfinite(gy)):
                raise ValueError(f"gravity must be finite, got ({gx}, {gy})")
            self.space.gravity = (gx, gy)
            self.gravity = grav

    # --- one control period -----------------------------------------------------------
    def run(self, s: np.ndarray, p: np.ndarray, u: np.ndarray) -> None:
        """Advance ``steps_per_control`` pymunk steps with the inputs ``u`` held.

        Per step: mesh spring forces from the positions at the start of the step, motor
        current and force from the pinion speed, friction levels from the speeds and the
        side loads of the previous step, then ``cpSpaceStep`` (the joints, the friction
        constraints, the mesh dampers and the pulp force functions).  The per-step reads
        and writes go through Chipmunk's C API (``pymunk.cp``) on the bodies and
        constraints that the pymunk objects wrap.
        """
        self.apply_inputs(u)
        (h, inv_h, n_steps, n_sens, mp, g, r_ohm, ke, kt, decay, pf_c, pf_s, gear_mu, vs,
         half_gap, k_mesh, rf_c0, rf_ratio, rod_mu,
         pin, pin_fric, ra, rb, fr_a, fr_b, ba1, ba2, bb1, bb2, dmp_a, dmp_b, c_space,
         area_model, fsr_n, share_w, stopped, x_min, x_max) = self._const
        cp = _cp
        get_p, get_v, set_f = cp.cpBodyGetPosition, cp.cpBodyGetVelocity, cp.cpBodySetForce
        set_p, set_v = cp.cpBodySetPosition, cp.cpBodySetVelocity
        get_j, set_max, c_step = cp.cpConstraintGetImpulse, cp.cpConstraintSetMaxForce, cp.cpSpaceStep
        strib, cur = _stribeck, _current_step
        mesh_state, flank = self._mesh_state, mesh_flank
        sup = u[U.driver_supply_v]
        v_cmd = min(max(u[U.command_v], -sup), sup)
        jammed = u[U.motor_jammed] > 0.0
        gx, gy = self.gravity
        f_pin_x = -mp * gx
        f_pin_g = -mp * gy
        eng_a, eng_b = self.engaged
        fc = self.fc
        inv_n = 1.0 / fsr_n
        f_sensor = self.f_sensor
        i_a = self.current_a
        energy = 0.0
        na = nb = fm_a = fm_b = lim_a = lim_b = 0.0
        for k in range(n_steps):
            vp = get_v(pin).y
            if abs(vp) > V_MAX:
                raise FloatingPointError(f"the mechanism diverged (pinion speed {vp:.3g} m/s)")
            # mesh: the lumped law's dead zone decides the loaded flank of each mesh spring
            yp = get_p(pin).y
            dxa = yp - get_p(ra).y
            dxb = yp - get_p(rb).y
            sa = flank(dxa, half_gap)
            sb = flank(dxb, half_gap)
            if sa != eng_a:
                eng_a = sa
                mesh_state(dmp_a, sa)
            if sb != eng_b:
                eng_b = sb
                mesh_state(dmp_b, sb)
            fm_a = get_j(dmp_a) * inv_h          # spring + damping impulse of the last step
            fm_b = get_j(dmp_b) * inv_h
            # motor and pinion
            i_a = cur(i_a, v_cmd, vp * g, r_ohm, ke, decay)
            set_f(pin, (f_pin_x, kt * i_a * g + f_pin_g))
            load = gear_mu * (abs(fm_a) + abs(fm_b))
            set_max(pin_fric, math.inf if jammed else strib(abs(vp), pf_c + load, pf_s + load, vs))
            # racks: friction from the bushing side loads of the last step
            na = (get_j(ba1) + get_j(ba2)) * inv_h
            nb = (get_j(bb1) + get_j(bb2)) * inv_h
            fca = rf_c0 + rod_mu * na
            fcb = rf_c0 + rod_mu * nb
            lim_a = strib(abs(get_v(ra).y), fca, rf_ratio * fca, vs)
            lim_b = strib(abs(get_v(rb).y), fcb, rf_ratio * fcb, vs)
            set_max(fr_a, lim_a)
            set_max(fr_b, lim_b)
            c_step(c_space, h)
            # end stops: the lumped law on the racks and the board
            for body in stopped:
                y = get_p(body).y
                if y < x_min or y > x_max:
                    y, vy = _end_stop(y, get_v(body).y, x_min, x_max)
                    set_p(body, (get_p(body).x, y))
                    set_v(body, (get_v(body).x, vy))
            # pulp forces of this step (set by the force functions) -> sensor
            if area_model:
                acc = 0.0
                for f in fc:
                    if f > 0.0:
                        acc += f ** fsr_n
                f_sensor[k] = (share_w * acc) ** inv_n
            else:
                f_sensor[k] = sum(fc)
            energy += v_cmd * i_a * h
        _sensor_sequence(s, p, u, f_sensor, n_sens)
        self.current_a = i_a
        self.engaged = [eng_a, eng_b]
        self.mesh_force_n = [fm_a, fm_b]
        self.side_load_n = [na, nb]
        self.rack_friction_limit_n = [lim_a, lim_b]
        self.rack_friction_n = [get_j(fr_a) * inv_h, get_j(fr_b) * inv_h]
        self.write_state(s, energy, h * n_steps)

    def write_state(self, s: np.ndarray, energy_j: float = 0.0, dt_s: float = 0.0) -> None:
        """Copy the mechanism's state into the flat state vector (lumped layout)."""
        cp = _cp
        pin, board = self.pinion._body, self.board._body
        s[S.current_a] = self.current_a
        s[S.pinion_pos_m] = cp.cpBodyGetPosition(pin).y
        s[S.pinion_vel_m_per_s] = cp.cpBodyGetVelocity(pin).y
        s[S.board_pos_m] = cp.cpBodyGetPosition(board).y
        s[S.board_vel_m_per_s] = cp.cpBodyGetVelocity(board).y
        s[S.prony_1_n], s[S.prony_2_n], s[S.prony_3_n] = sum(self.h1), sum(self.h2), sum(self.h3)
        s[S.elastic_force_n] = sum(self.fe)
        s[S.contact_force_n] = sum(self.fc)
        s[S.energy_j] += energy_j
        s[S.time_s] += dt_s

    # --- views ------------------------------------------------------------------------
    @property
    def tilt_rad(self) -> float:
        """Board tilt, rad (positive: the rack B side is higher)."""
        return self.board.angle

    def snapshot(self, s: np.ndarray | None = None) -> dict:
        """Plain-float picture of the mechanism for drawing and traces."""
        pose = self.pose or (0.0, 0.0, 0.0)
        out = {
            "t_s": float(s[S.time_s]) if s is not None else 0.0,
            "board_x_m": float(self.board.position.x), "board_y_m": float(self.board.position.y),
            "tilt_rad": float(self.board.angle),
            "rack_y_m": [float(r.position.y) for r in self.racks],
            "pinion_y_m": float(self.pinion.position.y),
            "finger_y_m": float(pose[0]), "press_offset_m": float(pose[1]), "finger_tilt_rad": float(pose[2]),
            "contact_x_m": [float(pose[1]) + x for x in self.xi],
            "contact_force_n": [float(f) for f in self.fc],
            "rack_friction_n": [float(f) for f in self.rack_friction_n],
            "rack_friction_limit_n": [float(f) for f in self.rack_friction_limit_n],
            "side_load_n": [float(f) for f in self.side_load_n],
            "mesh_force_n": [float(f) for f in self.mesh_force_n],
            "current_a": float(self.current_a),
        }
        if s is not None:
            out["force_est_n"] = float(s[S.force_est_n])
            out["force_true_n"] = float(s[S.contact_force_n])
        return out


# --------------------------------------------------------------------------------------
# the plant
# --------------------------------------------------------------------------------------

_RECORDERS: list = []


class PymunkPlant(Plant):
    """``n`` devices simulated as pymunk mechanisms, with the :class:`~ebraille_sim.plant.loop.Plant` interface.

    ``state``, ``params`` and ``inputs`` have the lumped layout (:mod:`ebraille_sim.plant.layout`);
    after every :meth:`advance` the state slots the runner reads (contact force, estimate,
    FSR voltage, current, board position, energy, time) are current.  Inputs beyond the
    lumped ones: ``press_offset_m`` (lateral offset of the press centre from the board
    centre), ``finger_tilt_rad`` (pulp surface tilt relative to the board) and
    ``gravity_lateral_m_per_s2``.
    """

    mechanisms: list
    mech: MechanismParams

    @classmethod
    def from_devices(cls, devices, seeds, board_pos_m=None, models=None, mechanism=None,
                     **overrides) -> "PymunkPlant":
        """Build ``len(devices)`` mechanisms.

        Parameters
        ----------
        devices, seeds, board_pos_m, models
            As :meth:`ebraille_sim.plant.loop.Plant.from_devices`.
        mechanism : MechanismParams, optional
            Geometry and model options (default :class:`MechanismParams`).
        **overrides
            Field changes of ``mechanism`` (e.g. ``mesh="elastic"``, ``physics_rate_hz=10000``);
            an unknown name is an error that lists the allowed ones.
        """
        mech = mechanism if mechanism is not None else MechanismParams()
        if overrides:
            mech = replace_checked(mech, **overrides)
        devices, params, states, inputs = pack_devices(devices, seeds, board_pos_m, models)
        rates = devices[0].rates
        mechs = [_Mechanism(dvc, mech, pk, sk[S.board_pos_m]) for dvc, pk, sk in zip(devices, params, states)]
        plant = cls(np.array(states), np.array(params), inputs, rates.substeps_per_control,
                    1.0 / rates.control_rate_hz, devices)
        plant.mechanisms = mechs
        plant.mech = mech
        for m_k, u_k in zip(mechs, inputs):
            m_k.apply_inputs(u_k)
        for rec in _RECORDERS:
            rec.attach(plant)
        return plant

    def advance(self, command_v) -> None:
        """Advance every device by one control period with ``command_v`` (V) held."""
        if len(self.mechanisms) == 1 and isinstance(command_v, (float, int)):
            c = float(command_v)
            if not math.isfinite(c):
                raise ValueError(f"command_v must be finite, got {c}")
            self.inputs[0, U.command_v] = c
        else:
            cmd = np.broadcast_to(np.asarray(command_v, dtype=float), (self.n,))
            if not np.all(np.isfinite(cmd)):
                raise ValueError("command_v must be finite for every device")
            self.inputs[:, U.command_v] = cmd
        for k, mech in enumerate(self.mechanisms):
            mech.run(self.state[k], self.params[k], self.inputs[k])
        for rec in _RECORDERS:
            rec.after_step(self)

    def set_pose(self, press_offset_m=None, finger_tilt_rad=None) -> None:
        """Lateral offset of the press centre (m) and tilt of the pulp surface (rad)."""
        if press_offset_m is not None:
            self.inputs[:, U.press_offset_m] = press_offset_m
        if finger_tilt_rad is not None:
            self.inputs[:, U.finger_tilt_rad] = finger_tilt_rad

    @property
    def tilt_rad(self) -> np.ndarray:
        """Board tilt of every device, rad, shape (n,)."""
        return np.array([m.tilt_rad for m in self.mechanisms])

    @property
    def rack_friction_n(self) -> np.ndarray:
        """Guide friction on racks A and B during the last step, N, shape (n, 2)."""
        return np.array([m.rack_friction_n for m in self.mechanisms])

    @property
    def rack_friction_limit_n(self) -> np.ndarray:
        """Break-away (stuck) or kinetic friction level of racks A and B, N, shape (n, 2)."""
        return np.array([m.rack_friction_limit_n for m in self.mechanisms])

    @property
    def side_load_n(self) -> np.ndarray:
        """Sum of the two bushing side loads of racks A and B, N, shape (n, 2)."""
        return np.array([m.side_load_n for m in self.mechanisms])

    def snapshot(self, k: int = 0) -> dict:
        """Plain-float picture of device ``k`` (see :func:`draw_snapshot`)."""
        snap = self.mechanisms[k].snapshot(self.state[k])
        snap["geometry"] = self.mech
        snap["device"] = self.devices[k]
        return snap

    def render(self, k: int = 0, size_px=(480, 360)) -> np.ndarray:
        """RGB picture of device ``k``, uint8 array of shape (height, width, 3)."""
        return draw_snapshot(self.snapshot(k), size_px=size_px)


# --------------------------------------------------------------------------------------
# recording and drawing
# --------------------------------------------------------------------------------------

class _Recorder:
    def __init__(self, every_s: float, device_index: int):
        if not (math.isfinite(every_s) and every_s > 0):
            raise ValueError(f"recording interval must be a positive number of seconds, got {every_s}")
        self.every_s = every_s
        self.k = device_index
        self.frames: list[dict] = []
        self.plants: list = []
        self._next = 0.0

    def attach(self, plant) -> None:
        self.plants.append(plant)
        self.frames.append(plant.snapshot(self.k))
        self._next = self.every_s

    def after_step(self, plant) -> None:
        if plant is not self.plants[-1]:
            return
        t = plant.state[self.k, S.time_s]
        if t >= self._next - 1e-12:
            self.frames.append(plant.snapshot(self.k))
            self._next += self.every_s


@contextlib.contextmanager
def recording(every_s: float = 0.04, device_index: int = 0):
    """Record snapshots of every :class:`PymunkPlant` built inside the ``with`` block.

    Examples
    --------
    >>> from ebraille_sim.scenarios.runner import run_scenario
    >>> with recording(every_s=0.05) as rec:
    ...     _ = run_scenario("contact_onset", backend="pymunk", duration_s=1.0)
    >>> len(rec.frames)
    21
    """
    rec = _Recorder(every_s, device_index)
    _RECORDERS.append(rec)
    try:
        yield rec
    finally:
        _RECORDERS.remove(rec)


def _gear_outline(cx, cy, r, teeth, angle, depth):
    t = np.linspace(0.0, 2.0 * np.pi, teeth * 8 + 1)
    rr = r + depth * 0.5 * np.sign(np.sin(teeth * (t - angle)))
    return cx + rr * np.cos(t), cy + rr * np.sin(t)


def draw_snapshot(snap: dict, size_px=(480, 360), tilt_gain: float = 20.0) -> np.ndarray:
    """Draw one mechanism snapshot; returns an RGB uint8 array (height, width, 3).

    Lengths are drawn to scale in millimetres, except the board tilt, which is magnified
    ``tilt_gain`` times (it is a few milliradians) and labelled so.
    """
    import matplotlib
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle, Polygon, Rectangle
    geo: MechanismParams = snap["geometry"]
    dev: DeviceParams = snap["device"]
    mm = 1e3
    w_px, h_px = size_px
    fig = Figure(figsize=(w_px / 100.0, h_px / 100.0), dpi=100)
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_axes((0.02, 0.1, 0.96, 0.88))
    s = geo.rod_spacing_m * mm
    travel = (dev.drivetrain.travel_max_m - dev.drivetrain.travel_min_m) * mm
    y0 = dev.drivetrain.travel_min_m * mm
    # frame and rods
    ax.add_patch(Rectangle((-0.5 * s - 3, y0 - geo.rack_length_m * mm - 4), s + 6, 1.5, color="0.35"))
    for x in (-0.5 * s, 0.5 * s):
        ax.plot([x, x], [y0 - geo.rack_length_m * mm - 2.5, y0 + travel + 1.5], color="0.55", lw=2)
    # racks
    cmap = matplotlib.colormaps["viridis"]
    fmax = max(1e-9, 0.3)
    for i, (x, yr) in enumerate(zip((-0.5 * s, 0.5 * s), snap["rack_y_m"])):
        yr *= mm
        fric = snap["rack_friction_n"][i]
        ax.add_patch(Rectangle((x - 0.5 * geo.rack_width_m * mm, yr - geo.rack_length_m * mm),
                               geo.rack_width_m * mm, geo.rack_length_m * mm,
                               color=cmap(min(abs(fric) / fmax, 1.0)), ec="k", lw=0.6))
        ax.text(x, yr - geo.rack_length_m * mm - 1.2, f"{fric:.2f} N", ha="center", va="top", fontsize=7)
    # pinion (drawn on the shaft, rotated by its travel / r)
    r = dev.drivetrain.pinion_radius_m * mm
    yc = y0 - 0.5 * geo.rack_length_m * mm
    ang = snap["pinion_y_m"] * mm / r
    gx, gy = _gear_outline(0.0, yc, r, 16, ang, 0.35)
    ax.fill(gx, gy, color="#c9a227", ec="k", lw=0.6)
    ax.plot([0.0, r * 0.8 * math.cos(ang)], [yc, yc + r * 0.8 * math.sin(ang)], color="k", lw=1)
    ax.plot([-0.5 * s + 0.5 * geo.rack_width_m * mm, -r], [yc, yc], color="0.4", lw=0.8, ls=":")
    ax.plot([r, 0.5 * s - 0.5 * geo.rack_width_m * mm], [yc, yc], color="0.4", lw=0.8, ls=":")
    # board (tilt magnified)
    th = snap["tilt_rad"] * tilt_gain
    bx, by = snap["board_x_m"] * mm, snap["board_y_m"] * mm
    wb, tb = geo.board_width_m * mm, geo.board_thickness_m * mm
    c, sn = math.cos(th), math.sin(th)
    corners = [(-0.5 * wb, 0.0), (0.5 * wb, 0.0), (0.5 * wb, -tb), (-0.5 * wb, -tb)]
    pts = [(bx + c * px - sn * py, by + sn * px + c * py) for px, py in corners]
    ax.add_patch(Polygon(pts, closed=True, color="#2e7d32", ec="k", lw=0.6))
    for col in (-0.5, 0.5):                         # display electrodes (two columns)
        px = col * 2.34
        ax.add_patch(Circle((bx + c * px, by + sn * px + 0.25), 0.72, color="#ffb300", ec="k", lw=0.4))
    # finger: a pad of radius PAD_RADIUS_MM about the press centre, flattened where the board presses it
    fy = snap["finger_y_m"] * mm
    xc = snap["press_offset_m"] * mm
    tt = math.tan(snap["finger_tilt_rad"])
    xs = np.linspace(xc - 9.0, xc + 9.0, 121)
    free = fy + (xs - xc) * tt + (xs - xc) ** 2 / (2.0 * PAD_RADIUS_MM)
    board_top = by + (xs - bx) * math.tan(th)
    on_board = np.abs(xs - bx) <= 0.5 * wb
    surf = np.where(on_board, np.maximum(free, board_top), free)
    ax.fill_between(xs, surf, fy + 9.0, color="#f4c7a1", ec="#a0522d", lw=0.8)
    fmax_c = max(max(snap["contact_force_n"]), 1e-9)
    for xcj, fj in zip(snap["contact_x_m"], snap["contact_force_n"]):
        xcj *= mm
        if fj > 0:
            y_c = by + (xcj - bx) * math.tan(th)
            ax.annotate("", xy=(xcj, y_c), xytext=(xcj, y_c + 0.8 + 3.0 * fj / fmax_c),
                        arrowprops=dict(arrowstyle="->", color="#b71c1c", lw=1.2))
    ax.set_xlim(-0.5 * s - 6, 0.5 * s + 6)
    ax.set_ylim(y0 - geo.rack_length_m * mm - 5, y0 + travel + 10)
    ax.set_aspect("equal")
    ax.axis("off")
    label = (f"t {snap['t_s']:.3f} s   F {snap.get('force_true_n', sum(snap['contact_force_n'])):.2f} N"
             f"   est {snap.get('force_est_n', float('nan')):.2f} N   tilt {snap['tilt_rad'] * 1e3:.2f} mrad"
             f" (drawn x{tilt_gain:g})")
    fig.text(0.02, 0.03, label, fontsize=7)
    canvas.draw()
    buf = np.asarray(canvas.buffer_rgba())
    return np.ascontiguousarray(buf[:, :, :3])


def draw_mechanism(plant: PymunkPlant, k: int = 0, size_px=(480, 360)) -> np.ndarray:
    """RGB picture (height, width, 3) of device ``k`` of a :class:`PymunkPlant`."""
    return plant.render(k, size_px)


def write_animation(frames: list, path, fps: float = 25.0, size_px=(480, 360), progress=None):
    """Write recorded snapshots as a GIF (Pillow) or, without Pillow, as numbered PNG frames.

    Parameters
    ----------
    frames : list of dict
        Snapshots from :func:`recording`.
    path : path
        The GIF; without Pillow, the folder ``path`` without its suffix receives
        ``frame_00000.png`` ... (earlier ``frame_*.png`` there are removed first).
    fps : float
        Frames per second of the GIF.
    size_px : (int, int)
        Width and height of a frame, px.
    progress : callable, optional
        Called as ``progress(done, total)`` after each frame is drawn.

    Returns
    -------
    pathlib.Path
        The path written (the GIF, or the folder of PNG frames).
    """
    import pathlib
    path = pathlib.Path(path)
    if not frames:
        raise ValueError("no frames to animate")
    try:
        import PIL  # noqa: F401
        have_pillow = True
    except ModuleNotFoundError:
        have_pillow = False
    images = []
    for f in frames:
        images.append(draw_snapshot(f, size_px=size_px))
        if progress is not None:
            progress(len(images), len(frames))
    path.parent.mkdir(parents=True, exist_ok=True)
    if have_pillow:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.animation as animation
        import matplotlib.pyplot as plt
        fig = plt.figure(figsize=(size_px[0] / 100.0, size_px[1] / 100.0), dpi=100)
        ax = fig.add_axes((0, 0, 1, 1))
        ax.axis("off")
        im = ax.imshow(images[0])

        def update(i):
            im.set_data(images[i])
            return (im,)
        anim = animation.FuncAnimation(fig, update, frames=len(images), blit=True)
        out = path if path.suffix.lower() == ".gif" else path.with_suffix(".gif")
        anim.save(str(out), writer=animation.PillowWriter(fps=fps))
        plt.close(fig)
        return out
    import matplotlib.image as mpimg
    folder = path.with_suffix("")
    folder.mkdir(parents=True, exist_ok=True)
    for old in folder.glob("frame_*.png"):
        old.unlink()
    for i, img in enumerate(images):
        mpimg.imsave(folder / f"frame_{i:05d}.png", img)
    return folder


# --------------------------------------------------------------------------------------
# the [mechanism] scenario section
# --------------------------------------------------------------------------------------

PAD_RADIUS_MM = 8.0
"""Fingertip pad radius used for drawing, mm [E] (as in the Hertz estimate of contact_width_m)."""
