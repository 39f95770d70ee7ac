"""Scheduled PID with Coulomb-friction compensation keyed on the force error.

The gearhead is not back-drivable: between pushing and pulling the board the command must
cross a friction band of width ``2 R / (kM g) (mu r + Fc)`` (about 0.7 V at 1 N on the
nominal drive, ``R`` winding resistance, ``kM`` motor constant, ``g = N/r`` the gear
reflection of :func:`ebraille_sim.physics.drivetrain.shaft_to_rack_per_m`, ``mu`` the
load-dependent gear loss, ``Fc`` the pinion and guide Coulomb friction).  While the command
is inside the band the board does not move, so a PID that must reverse the drive - every
time the finger presses in and then relaxes - first integrates across the band; at
its ``ki = 1.8 V/(N s)`` and an error of one band width (0.1 N) that takes seconds,
and the force drifts out of band meanwhile.  That is what limits the shipped PIDs on
``pressing_90wpm`` and ``battery_sag`` (docs/benchmark.md): ``actuator_bound`` with the
same feedforward and true-force feedback holds those scenarios in band.

The compensation is the classic model-based Coulomb feedforward (Armstrong-Helouvry,
Dupont & Canudas de Wit, *Automatica* 30(7), 1994, section 6) with the sign taken from the
force error rather than from the (unmeasured) velocity: the feedforward of
:class:`controllers.schedule.ScheduledPID`::

    u_ff = R / (kM g) [ (1 + s mu) r + s Fc ] + kE g r' / K(r)

already holds the command on the edge of the band in the direction ``s`` of the last
setpoint movement; here ``s`` also follows the sign of the force error ``e = r_map - y``
once ``|e|`` exceeds ``hysteresis_fraction`` of the setpoint, so a correction in the
opposite direction jumps the command to the other edge of the band at once instead of
integrating across it.  The hysteresis keeps sensor noise (a few mN on the estimate) from
toggling ``s``; the setpoint-rate rule of the parent keeps precedence during ramps.  Only
``friction_fraction`` = 70 % of the modelled term is compensated: the drawn drives carry
less friction than the nominal model on some readers, and full compensation made one of
them limit-cycle at contact (docs/benchmark.md).

The gains are :data:`FRICTION_GAINS`, kp 0.81 V/N, ki 1.8 V/(N s), kd 0.011 V s/N at 1 N: the
scheduled PID's recommended design until the Ms <= 2.0 tuning replaced it
(:data:`controllers.schedule.RECOMMENDED`, kp 0.859, ki 1.72, kd 0.00348).  Here they stay,
because on the standard benchmark (8 readers, docs/benchmark.md) this controller scores
63.04 with them and 62.12 with the new design, which also lowers its worst reader on
``strap_slip`` from 0.97 to 0.84 in band, on ``battery_sag`` from 0.61 to 0.56 and on
``refresh_60wpm`` from 0.16 to 0.06, and raises its highest peak from 2.13 to 2.32 N; it gains
only on steady reading (0.99 to 1.00), ``contact_onset`` (0.95 to 1.00) and
``setpoint_steps`` (0.67 to 0.74).  Raising the gains further helps ``pressing_90wpm`` a
little more but drives ``refresh_120wpm`` to peaks above 3 N.

Examples
--------
>>> from controllers import make
>>> c = make("pid_friction")
>>> c.reset(force_est_n=1.0, setpoint_n=1.0, command_v=0.0)
>>> u_push = c.update(0.8, 1.0, 1e-3)
>>> c.reset(force_est_n=1.0, setpoint_n=1.0, command_v=0.0)
>>> u_pull = c.update(1.2, 1.0, 1e-3)
>>> u_push - u_pull > 0.5          # the two edges of the friction band, plus the P action
True
"""
from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ebraille_sim.base.fields import sourced
from ebraille_sim.base.validation import check_keys, check_number, replace_checked
from ebraille_sim.physics.params import DeviceParams

from controllers.compiled import feedforward_v as compiled_feedforward_v
from controllers.pid import GAIN_SOURCE, pid_field
from controllers.schedule import ScheduleConfig, ScheduledPID

__all__ = ["FrictionConfig", "FrictionPID", "FRICTION_GAINS", "DEFAULT_FRICTION", "make_friction"]

FRICTION_GAINS = {"kp_v_per_n": 0.81, "ki_v_per_ns": 1.8, "kd_vs_per_n": 0.011}
"""The PID gains of ``pid_friction`` at 1 N (module docstring: why not :data:`controllers.schedule.RECOMMENDED`'s)."""


@dataclass(frozen=True)
class FrictionConfig(ScheduleConfig):
    """:class:`~controllers.schedule.ScheduleConfig` (feedforward and reference map on, the
    gains of :data:`FRICTION_GAINS`) plus the friction compensation's two settings.

    Parameters
    ----------
    friction_fraction : float
        Fraction of the modelled Coulomb term ``s R/(kM g) (mu r + Fc)`` compensated, in
        [0, 1]; below 1 it leaves margin for devices with less friction than the nominal model.
    hysteresis_fraction : float
        Error, as a fraction of ``max(r, 0.2 N)``, beyond which the friction direction
        follows the sign of the error; in [0, 1).

    Raises
    ------
    ValueError
        One line naming the offending field (also every :class:`ScheduleConfig` check), or
        when ``feedforward`` is off (the friction term is part of the feedforward).
    """
    kp_v_per_n: float = pid_field("kp_v_per_n", FRICTION_GAINS["kp_v_per_n"])
    ki_v_per_ns: float = pid_field("ki_v_per_ns", FRICTION_GAINS["ki_v_per_ns"])
    kd_vs_per_n: float = pid_field("kd_vs_per_n", FRICTION_GAINS["kd_vs_per_n"])
    feedforward: bool = sourced(True, "-", GAIN_SOURCE, doc="Add the model feedforward (needed: the friction term "
                                                            "is part of it).")
    friction_fraction: float = sourced(0.7, "-", GAIN_SOURCE, doc="Fraction of the modelled Coulomb friction "
                                                                  "compensated.")
    hysteresis_fraction: float = sourced(0.02, "-", GAIN_SOURCE, doc="Error, a fraction of max(r, 0.2 N), beyond "
                                                                     "which the friction direction follows the "
                                                                     "error's sign.")

    def __post_init__(self):
        super().__post_init__()
        object.__setattr__(self, "friction_fraction",
                           check_number("friction_fraction", self.friction_fraction, 0.0, 1.0))
        object.__setattr__(self, "hysteresis_fraction",
                           check_number("hysteresis_fraction", self.hysteresis_fraction, 0.0, 1.0, hi_open=True))
        if not self.feedforward:
            raise ValueError("pid_friction needs feedforward = true (the friction term is part of it)")

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], *, base: FrictionConfig | None = None) -> FrictionConfig:
        """A config from field values; omitted fields from ``base`` (default :data:`DEFAULT_FRICTION`)."""
        return replace_checked(DEFAULT_FRICTION if base is None else base, **d)


DEFAULT_FRICTION = FrictionConfig()
"""The shipped design: the gains of :data:`FRICTION_GAINS`, 70 % of the modelled friction,
2 % hysteresis (docs/benchmark.md)."""


class FrictionPID(ScheduledPID):
    """:class:`~controllers.schedule.ScheduledPID` whose friction direction follows the force error.

    Parameters
    ----------
    config : FrictionConfig
    device : DeviceParams
        Nominal device of the friction and motor model.
    """

    def __init__(self, config: FrictionConfig = DEFAULT_FRICTION, device: DeviceParams = DeviceParams(),
                 name: str = "pid_friction"):
        if not isinstance(config, FrictionConfig):
            raise TypeError(f"config must be a FrictionConfig, got {type(config).__name__}")
        super().__init__(config, device=device, name=name)

    def _friction_params(self) -> dict:
        """The friction compensation's parameters of the compiled step: on, its fraction and
        its hysteresis (the direction latch on the error runs in
        :func:`controllers.compiled.pid_step`, before the parent's setpoint-rate rule)."""
        return {"friction": 1.0, "friction_fraction": self.config.friction_fraction,
                "hysteresis_fraction": self.config.hysteresis_fraction}

    def feedforward_v(self, setpoint_n: float, rate_n_per_s: float, direction: float = 1.0) -> float:
        """The parent's ``u_ff`` with its friction part scaled by ``friction_fraction``."""
        return compiled_feedforward_v(self._p, float(setpoint_n), float(rate_n_per_s), float(direction))


_FIELDS = tuple(f.name for f in dataclasses.fields(FrictionConfig))


def make_friction(**gains: Any) -> FrictionPID:
    """Registry factory ``"pid_friction"``: :class:`FrictionConfig` fields over :data:`DEFAULT_FRICTION`."""
    check_keys("the gains of pid_friction", gains, _FIELDS)
    return FrictionPID(FrictionConfig.from_dict(gains))
