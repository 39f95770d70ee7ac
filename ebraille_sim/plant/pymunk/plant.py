"""``n`` devices as pymunk mechanisms behind the lumped plant's interface.

:class:`PymunkPlant` packs the devices as the lumped plant does
(:func:`~ebraille_sim.plant.lumped.pack_devices`), builds one
:class:`~ebraille_sim.plant.pymunk.model.Mechanism` per device and advances them by one
control period in :meth:`PymunkPlant.advance`; the plant backend ``"pymunk"``
(:data:`ebraille_sim.plant.backends.PLANT_BACKENDS`).  An optional recorder
(:class:`~ebraille_sim.plant.pymunk.recording.Recorder`) is handed to it when it is built.

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

import math

import numpy as np

from ebraille_sim.physics.params import replace_checked
from ebraille_sim.plant.layout import S, U
from ebraille_sim.plant.lumped import Plant, pack_devices
from ebraille_sim.plant.pymunk.geometry import MechanismParams
from ebraille_sim.plant.pymunk.model import Mechanism

__all__ = ["PymunkPlant"]


class PymunkPlant(Plant):
    """``n`` devices simulated as pymunk mechanisms, with the :class:`~ebraille_sim.plant.lumped.Plant` interface.

    ``state``, ``params`` and ``inputs`` have the lumped layout (:mod:`ebraille_sim.plant.layout`);
    after every :meth:`advance` the state slots the runner reads (contact force, estimate,
    FSR voltage, current, board position, energy, time) are current.  Inputs beyond the
    lumped ones: ``press_offset_m`` (lateral offset of the press centre from the board
    centre), ``finger_tilt_rad`` (pulp surface tilt relative to the board) and
    ``gravity_lateral_m_per_s2``.
    """

    mechanisms: list
    mech: MechanismParams
    recorder: object = None

    @classmethod
    def from_devices(cls, devices, seeds, board_pos_m=None, models=None, mechanism=None, recorder=None,
                     **overrides) -> "PymunkPlant":
        """Build ``len(devices)`` mechanisms.

        Parameters
        ----------
        devices, seeds, board_pos_m, models
            As :meth:`ebraille_sim.plant.lumped.Plant.from_devices`.
        mechanism : MechanismParams, optional
            Geometry and model options (default :class:`MechanismParams`).
        recorder : Recorder, optional
            Takes a snapshot of the plant when it is built (``recorder.attach(plant)``) and
            is handed the plant after every :meth:`advance` (``recorder.after_step(plant)``):
            :class:`ebraille_sim.plant.pymunk.recording.Recorder`.
        **overrides
            Field changes of ``mechanism`` (e.g. ``mesh_offset_m=0.0``, ``physics_rate_hz=10000``);
            an unknown name is an error that lists the allowed ones.
        """
        mech = mechanism if mechanism is not None else MechanismParams()
        if overrides:
            mech = replace_checked(mech, **overrides)
        devices, params, states, inputs = pack_devices(devices, seeds, board_pos_m, models)
        rates = devices[0].rates
        mechs = [Mechanism(dvc, mech, pk, sk[S.board_pos_m]) for dvc, pk, sk in zip(devices, params, states)]
        plant = cls(np.array(states), np.array(params), inputs, rates.substeps_per_control,
                    1.0 / rates.control_rate_hz, devices)
        plant.mechanisms = mechs
        plant.mech = mech
        for m_k, u_k in zip(mechs, inputs):
            m_k.apply_inputs(u_k)
        if recorder is not None:
            plant.recorder = recorder
            recorder.attach(plant)
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
        if self.recorder is not None:
            self.recorder.after_step(self)

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
        """Plain-float picture of device ``k``: its mechanism's snapshot
        (:meth:`~ebraille_sim.plant.pymunk.model.Mechanism.snapshot`) with the geometry and the
        device (what :func:`ebraille_sim.tools.mechanism_drawing.draw_snapshot` draws)."""
        snap = self.mechanisms[k].snapshot(self.state[k])
        snap["geometry"] = self.mech
        snap["device"] = self.devices[k]
        return snap
