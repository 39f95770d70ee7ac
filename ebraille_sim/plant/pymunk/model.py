"""The pymunk model of one device: bodies, joints, the per-step physics outside Chipmunk.

The lumped plant (:mod:`ebraille_sim.plant.kernel`) moves the drive train and the board as one
body on a line.  :class:`Mechanism` builds the same device as a planar linkage in the
cross-section of the finger (``x`` across the finger, ``y`` along the board travel, toward
the pulp)::

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
  the teeth are in contact and solved implicitly by Chipmunk.  The spring is linearly
  implicit: while the teeth touch, its damping is ``c + k h``, and the spring force from the
  old position plus an implicit damper ``k h`` is the backward-Euler step ``F = k x_new``,
  stable at any step (its extra damping acts on the parasitic ~400 Hz mesh mode only).
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
  does not touch the board.  These springs stay explicit; the step they allow is
  :func:`ebraille_sim.plant.pymunk.geometry.check_mechanism_step`'s.
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

Examples
--------
>>> from ebraille_sim.physics.params import DeviceParams
>>> from ebraille_sim.plant.lumped import pack_devices
>>> from ebraille_sim.plant.pymunk.geometry import MechanismParams
>>> devices, params, states, inputs = pack_devices([DeviceParams()], [1])
>>> m = Mechanism(devices[0], MechanismParams(), params[0], states[0][S.board_pos_m])
>>> m.apply_inputs(inputs[0])
>>> m.run(states[0], params[0], inputs[0])         # one control period, no command
>>> m.steps_per_control, round(m.h * 1e6)
(5, 200)
"""
from __future__ import annotations

import math

import numpy as np
import pymunk

from ebraille_sim.base.compiled import njit
from ebraille_sim.physics.drivetrain import end_stop, mesh_force, stribeck
from ebraille_sim.physics.fingertip import contact_force, elastic_force, prony_coefficients, prony_step
from ebraille_sim.physics.motor import current_decay, current_step
from ebraille_sim.physics.params import DeviceParams
from ebraille_sim.plant import kernel
from ebraille_sim.plant.layout import P, S, U
from ebraille_sim.plant.pymunk.geometry import MechanismParams, check_mechanism_step

__all__ = ["Mechanism", "mesh_flank", "V_MAX"]

# scalar laws, called from Python on the pymunk path (the same code the kernel compiles);
# the mesh law (drivetrain.mesh_force) picks the loaded flank (mesh_flank) and is set into
# the mesh DampedSprings by Mechanism._mesh_state
_stribeck = stribeck.py_func
_elastic = elastic_force.py_func
_prony_step = prony_step.py_func
_contact_force = contact_force.py_func
_current_step = current_step.py_func
_mesh_force = mesh_force.py_func
_end_stop = end_stop.py_func
_cp = pymunk.cp

V_MAX = 10.0
"""Speed (m/s) of the pinion beyond which a run is reported as diverged (no-load speed: 0.06 m/s)."""


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


class Mechanism:
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
            1.0 / p[P.motor_r_ohm], p[P.motor_ke], p[P.motor_kt], decay,
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
        (h, inv_h, n_steps, n_sens, mp, g, g_arm, ke, kt, decay, pf_c, pf_s, gear_mu, vs,
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
            i_a = cur(i_a, v_cmd, vp * g, g_arm, ke, decay)
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
