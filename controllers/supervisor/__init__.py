"""Safety supervisor: wraps any controller and keeps the finger safe when something fails.

The supervisor sees what the controller sees (estimated force, setpoint, time step,
motor current) and the command the inner controller proposes.  In normal running it
only shapes that command; when it detects a fault it takes over.

Shaping (every period, in this order)
-------------------------------------
1. **Watchdog.**  A non-finite command is replaced by 0 V (the drive is not
   back-drivable, so the board holds still).  When the inner controller returns a finite
   command again it is reset bumplessly from 0 V and takes over at the next period; a
   non-finite stretch longer than ``watchdog_timeout_s`` is a latched fault.
2. **Force cap.**  The setpoint passed to the inner controller is clipped to
   ``force_cap_n - cap_margin_n``, or lower to the setpoint that leaves room for a strap slip
   toward the board (``slip_headroom_m`` over ``slip_time_s``, :mod:`controllers.supervisor.motion`:
   2.68 N for the default 0.1 mm in 20 ms).  Inside the soft zone ``[cap - margin, cap]`` a pushing
   command is scaled by ``1 - v`` with ``v`` the degree of violation in [0, 1]; at or
   above the cap the command is ``-retract_v`` until the estimate is back below it.
3. **Rate limit.**  The command moves at most ``slew_v_per_s`` per second.
4. **Current and speed envelope** (with a current measurement).  The command is capped at
   the voltage that brings the motor current to a limit that depends on the rack speed read
   from the back-EMF (highest of the last ``speed_hold_s``): at rest the current whose
   steady push (:mod:`ebraille_sim.physics.limits` eq. 1) is ``safe_force_n`` less the
   pulp's own motion; moving, the current whose push plus the impact of the moving drive
   stays there; above the speed limit a braking current.  This bounds the true force
   whatever the sensor reads (derivation and numbers: docs/safety.md).

Faults (latched: safe retract, then hold)
-----------------------------------------
================== =====================================================================
cause              detection
================== =====================================================================
fsr_out_of_range   estimate above ``out_of_range_n`` (a short reads the supply: ~15 N),
                   or not finite
fsr_stuck          (without a current measurement) in contact, over ``stuck_window_s`` the
                   estimate stays above ``contact_lost_n`` and moves less than
                   ``stuck_tolerance_n`` while the command of ``stuck_response_s`` earlier
                   moved more than ``stuck_command_v``; with a current measurement the
                   travel rule below decides
motor_overcurrent  I^2 t: ``theta = int (i^2 - I_rated^2) dt`` (kept >= 0) exceeds
                   ``(I_stall^2 - I_rated^2) overload_time_s``
contact_lost       after contact (estimate > ``contact_on_n``), a loss of contact
                   (estimate < ``contact_lost_n``, or a drop by more than ``drop_n`` within
                   ``drop_window_s`` to below ``drop_keep_fraction`` of the estimate at the
                   start of that window, while pushing) starts a *freeze*: back off at
                   ``-retract_v`` for ``backoff_s`` then hold 0 V; contact regained
                   (estimate > ``contact_on_n`` and not falling) resumes the inner
                   controller from 0 V.  No contact within ``contact_loss_timeout_s``: with a
                   current measurement the board re-approaches at ``reapproach_command_v``
                   (the speed whose push and impact stay at the top setpoint) and a contact
                   resumes as above; no contact within ``reapproach_travel_m`` beyond the
                   board's place at the loss, or within twice that travel's time, is latched
                   (an open FSR reads 0 V, i.e. no force, for good; a finger gone).  Without a
                   current measurement the timeout latches.
controller_nonfinite non-finite commands for longer than ``watchdog_timeout_s``
fsr_stuck          (travel) in contact, the estimate stays within ``stuck_tolerance_n`` while
                   the powered motor moves the board ``stuck_travel_m`` net (back and forth
                   cancels: the hysteresis compensation holds its estimate still while a
                   loop hunts inside the film's blind stretch)
fsr_implausible    moving forward, the force the current implies (lower edge of the friction
                   band) exceeds the recent estimate by ``implausible_n`` for
                   ``implausible_s``; or the travel since contact exceeds the soft reader's
                   compression for the estimate
fsr_no_contact     no contact within ``first_contact_travel_m`` of travel from the start
motor_stalled      pushing without moving for ``stall_time_s``, with no contact shown, or at
                   ``stall_fraction`` of the current limit while the push at the lower edge
                   of the friction band exceeds the recent estimate by ``implausible_n``,
                   short of ``end_stop_travel_m`` (beyond it: the board's far end stop)
================== =====================================================================

A fall of the setpoint within ``release_window_s`` (refresh release, a step down) widens the
drop that counts as a loss of contact by that fall, and an estimate below ``contact_lost_n``
is a loss only while the setpoint asks for contact.

*Safe retract*: ``-retract_v`` until the board has moved back for at least
``retract_moving_s`` (motion is read from the current: a moving motor draws much less than
``retract_v / R``) and then stalls on the end stop, or for ``max_retract_s`` at most; then
0 V (hold).  A jammed motor keeps retracting at ``retract_v / R`` (below the rated current)
until it frees itself.  Without a current measurement the retract lasts ``retract_s``.

Scenario section ``[supervisor]`` (:mod:`ebraille_sim.scenarios.supervision`): every
:class:`SupervisorPolicy` field may be given; ``enabled = false`` disables it.  The
:class:`DriveEnvelope` (motor, drive and reader constants) follows from ``[device]``: a
scenario cannot set it.

Compiled period
---------------
The supervisor's whole state (modes, detectors, the running min/max windows as ring buffers,
the event log) lives in one float64 array and its configuration in another
(:meth:`Supervisor.compiled`, :meth:`SupervisorConfig.pack`); one period is two compiled
functions around the inner controller, which the loop engine composes
(:func:`ebraille_sim.plant.engine.command`)::

    code, u, sp_inner = supervise_begin(sv, cfg, f, sp, dt, cur)       # cur NaN: no current
    if code == 1:                                   # run: the inner controller proposes
        u_inner = inner.update(f, sp_inner, dt, cur_or_None)
        code2, u, reset_cmd = supervise_end(sv, cfg, u_inner, f, sp, dt, cur)
        if code2 == 1:                              # finite command again: bumpless resume
            inner.reset(force_est_n=f, setpoint_n=sp_inner, command_v=reset_cmd)
        elif code2 == 2:                            # the search found the finger: start from 0 V
            inner.reset(force_est_n=f, setpoint_n=sp_inner, command_v=0.0)
    elif code == 2:                                 # contact regained: resume from 0 V,
        resume_controller(inner, force_est_n=f, setpoint_n=sp_inner)   # integrator not below 0 V
    # the command is u

:meth:`Supervisor.update` is exactly this.  The windows are sized for control periods of at
least :data:`MIN_CONTROL_PERIOD_S`; the event log keeps :data:`EVENT_CAPACITY` events.

The two functions are compiled without Numba's reference counting (``_nrt=False``: they
allocate nothing) and every helper of a normal period is inlined into them; only the rare
paths (a fault, an event, the safe states) call out.  Counting the references of the two
arrays at every helper, an atomic operation each, would cost more than the period's own
arithmetic.  They are compiled with NumPy's error model (``error_model="numpy"``): every divisor
in them is a configuration value checked positive, the control period (at least ``min_dt_s``) or
the difference of two of the envelope's increasing speeds, so no division checks for a zero
divisor, and a period costs about half (150 against 82 ns with the default controller in
``steady_90wpm``).

Examples
--------
>>> from controllers import make
>>> sup = Supervisor(make("pid"))
>>> sup.reset(force_est_n=0.0, setpoint_n=1.0)
>>> round(sup.update(0.0, 5.0, 1e-3), 4)      # setpoint clipped to 2.68 N; the PID's first step
0.0393
>>> round(sup.update(float("nan"), 1.0, 1e-3), 4)   # a NaN estimate: latched fault, retract (slew 0.6 V/ms)
-0.5607
>>> sup.fault, sup.mode
('fsr_out_of_range', 'retract')
"""
from __future__ import annotations

from controllers.supervisor.config import (CONTACT_ON_N, DESIGN_GAP_M, ESTIMATOR_PERIOD_S, FORCE_CAP_LIMIT_N,
                                           ENVELOPE_KEYS, POLICY_KEYS, RATED_CURRENT_A, RATED_TO_STALL,
                                           SAFE_FORCE_N, DriveEnvelope, SupervisorConfig, SupervisorPolicy,
                                           check_policy, _default_config, _packed_config, device_limits, rated_current_a)
from controllers.supervisor.envelope import ENVELOPE_POINTS, _envelope_memo, _envelope_table
from controllers.supervisor.layout import (CF, EVENT, EVENT_CAPACITY, FAULT, FAULTS, MAX_WINDOW_SAMPLES,
                                           MIN_CONTROL_PERIOD_S, MODE, MODES, SV, _initial_state, _pack,
                                           _reset_header)
from controllers.supervisor.detectors import _interp_envelope
from controllers.supervisor.period import supervise_begin, supervise_end
from controllers.supervisor.wrapper import Supervisor

__all__ = ["SupervisorConfig", "SupervisorPolicy", "DriveEnvelope", "POLICY_KEYS", "ENVELOPE_KEYS",
           "check_policy", "Supervisor", "RATED_CURRENT_A", "RATED_TO_STALL", "rated_current_a",
           "FORCE_CAP_LIMIT_N", "SAFE_FORCE_N", "device_limits", "supervise_begin", "supervise_end",
           "MIN_CONTROL_PERIOD_S", "MAX_WINDOW_SAMPLES", "EVENT_CAPACITY", "MODES", "FAULTS", "SV", "CF",
           "MODE", "FAULT", "EVENT", "CONTACT_ON_N", "DESIGN_GAP_M", "ESTIMATOR_PERIOD_S", "ENVELOPE_POINTS"]
