r"""The sampled-data plant and loop a controller sees, exact at the estimator rate.

:func:`linearize` returns the plant from the motor command (V) to the *estimated* force
(N) as a discrete ``control.StateSpace`` at an operating force in contact;
:func:`loop_models` closes it with a controller.  The continuous part is the contact plant
of :mod:`ebraille_sim.analysis.plant_model`; the sensor chain's discrete blocks are here
(:func:`creep_model`, :func:`compensation_model`, :func:`sensor_models`).

Sampled-data form (the method)
------------------------------
The controller runs at the control rate (1 kHz) and holds its command over each
control period; the ADC samples the divider once per period and the digital anti-alias
biquad runs at that rate; the estimator (the paper's Wiener model, linear block and the
slope of its output map at the operating point, then the two-sample mean) runs every
``N = rate_ctrl / rate_est`` samples (10).  Nothing here is approximated by a continuous
equivalent:

1. the continuous part above is discretised exactly at the control period (zero-order
   hold, which is what the kernel does: the command is held over the period);
2. it is put in series with the creep terms (:func:`creep_model`, at the sensor rate, as the
   kernel advances them), the estimator's creep compensation (:func:`compensation_model`:
   the partial derivatives of the kernel's own compensation, its creep terms driven by the
   estimate the firmware holds) and the anti-alias biquad at the same rate;
3. for the open-loop plant, the command is held over ``N`` control periods and the
   sampled model is lifted to the estimator rate (``A^N``, ``sum A^j B``) and put in series
   with the estimator: :func:`linearize` returns this model with ``dt`` = 0.01 s.  With the
   compensation the estimate is fed back into the front: the sample the estimator reads
   still holds the previous estimate, the ``N - 1`` after it the new one (:func:`_lift`);
4. for a loop with a controller that runs at the control rate (:func:`pid_statespace`),
   the controller and the plant are lifted together over ``N`` periods with the estimate
   held, which gives the exact loop transfer at the estimator rate (the only rate at which
   the measured signal changes).

Examples
--------
>>> from ebraille_sim.analysis.sampled import linearize
>>> P = linearize(force_n=1.0)
>>> P.dt
0.01
"""
from __future__ import annotations

import math

import control
import numpy as np
import scipy.signal

from ebraille_sim.analysis.plant_model import CONTINUOUS_STATES, OperatingPoint, continuous_model, operating_point
from ebraille_sim.analysis.sensor_point import compensation_point, sensor_point
from ebraille_sim.physics import fsr as _fsr
from ebraille_sim.physics.params import DeviceParams

__all__ = ["creep_model", "CREEP_STATES", "compensation_model", "COMP_STATES", "ESTIMATE_HELD_STATE",
           "sensor_models", "sampled_front", "linearize", "lift", "pid_statespace", "loop_models"]


CREEP_STATES = [f"fsr_creep_{j}_v" for j in range(_fsr.N_CREEP)]
"""States of :func:`creep_model`: the creep terms as divider-voltage deviations."""


def creep_model(device: DeviceParams = DeviceParams()) -> control.StateSpace:
    """Small-signal hereditary creep at the sensor rate, instantaneous voltage in, voltage out.

    The kernel advances every creep term once per sensor sample with
    :func:`ebraille_sim.physics.fsr.creep_state_step` (``z <- a z + (1 - a) F_eff``) and adds
    ``w sum_i z_i`` of the *new* states to the force (:func:`ebraille_sim.physics.fsr.creep_force`).
    Linear in its arguments, the law gives ``a`` and ``1 - a`` as its values on unit inputs;
    with the input ``x`` the instantaneous voltage deviation (slope times ``dF_l``, which
    scales the force deviation the terms follow by a constant), the model is
    ``zeta+ = a zeta + (1-a) x``, ``y = x + w sum_i (a_i zeta_i + (1-a_i) x)``, with the
    weight ``w`` and decays ``a_i`` that :func:`ebraille_sim.plant.lumped.pack_params` packs.
    Its gain is ``1 + w sum_i (1 - a_i)`` at the Nyquist frequency and ``1 + N w`` at DC.
    """
    fsr = device.fsr
    dt = 1.0 / device.rates.sensor_rate_hz
    w = _fsr.creep_term_weight(fsr.creep_per_decade, fsr.creep_tau_min_s, fsr.creep_tau_max_s)
    step = _fsr.creep_state_step.py_func
    a = np.array([step(1.0, 0.0, _fsr.creep_decay(dt, tau)) for tau in _fsr.creep_taus_s(fsr.creep_tau_min_s,
                                                                                            fsr.creep_tau_max_s)])
    b = np.array([step(0.0, 1.0, _fsr.creep_decay(dt, tau)) for tau in _fsr.creep_taus_s(fsr.creep_tau_min_s,
                                                                                            fsr.creep_tau_max_s)])
    return control.ss(np.diag(a), b.reshape(-1, 1), (w * a).reshape(1, -1), [[1.0 + w * float(np.sum(b))]],
                      dt=dt, inputs=["fsr_voltage_inst_v"], outputs=["fsr_voltage_v"], states=list(CREEP_STATES),
                      name="creep")


COMP_STATES = [f"comp_creep_{j}_n" for j in range(_fsr.N_CREEP)]
"""States of :func:`compensation_model`: the firmware's creep terms (deviations, N)."""

ESTIMATE_HELD_STATE = "est_held_n"
"""State of the lifted model with compensation: the estimate the compensation holds."""


def compensation_model(device: DeviceParams, op: OperatingPoint) -> control.StateSpace:
    """Small-signal creep compensation at the sensor rate.

    Inputs: the divider voltage (V) and the estimate the firmware holds (N); output: the
    voltage the anti-alias filter receives (V); states :data:`COMP_STATES`, the firmware's
    creep terms, advanced by :func:`ebraille_sim.physics.fsr.creep_state_step` on the held
    estimate (``zeta+ = a zeta + (1 - a) dF_est``).  The output is
    ``dv_out = d_v dv + d_F dF_est + sum_i d_zi zeta_i`` with the partial derivatives of
    the kernel's own compensation (:func:`~ebraille_sim.analysis.sensor_point.compensation_point`,
    old states as arguments).
    Without compensation the model passes the voltage through.
    """
    dt = 1.0 / device.rates.sensor_rate_hz
    if not device.estimator.creep_compensation:
        return control.ss(np.zeros((0, 0)), np.zeros((0, 2)), np.zeros((1, 0)), [[1.0, 0.0]], dt=dt,
                          inputs=["fsr_voltage_v", "force_est_held_n"], outputs=["fsr_voltage_comp_v"],
                          name="compensation")
    _, d_v, d_f, d_z, a = compensation_point(device, op.fsr_voltage_v, op.estimate_n, op.load_time_s)
    n = len(a)
    B = np.zeros((n, 2))
    B[:, 1] = 1.0 - a
    return control.ss(np.diag(a), B, d_z.reshape(1, -1), [[d_v, d_f]], dt=dt,
                      inputs=["fsr_voltage_v", "force_est_held_n"], outputs=["fsr_voltage_comp_v"],
                      states=list(COMP_STATES), name="compensation")


def sensor_models(device: DeviceParams = DeviceParams(), op: OperatingPoint | None = None, *,
                  force_n: float = 1.0, model=None) -> tuple[control.StateSpace, control.StateSpace]:
    """The digital anti-alias filter (at the sensor rate) and the linearised estimator.

    Returns
    -------
    aa : StateSpace, dt = 1/sensor_rate
        Tared divider voltage (V) to filtered voltage (V); states ``aa_z1``, ``aa_z2``.
    est : StateSpace, dt = the estimator model's period
        Filtered voltage (V) to estimated force (N): input-map slope, the linear block,
        the output-map slope at the operating point and (when enabled) the two-sample mean;
        states ``est_z0...`` and ``est_raw_prev_n``.
    """
    if op is None:
        op = operating_point(device, force_n)
    r = device.rates
    bb, aa = scipy.signal.butter(2, device.estimator.antialias_cutoff_hz, fs=r.sensor_rate_hz)
    # DF2T realisation exactly as the kernel runs it
    b0, b1, b2 = bb
    a1, a2 = aa[1], aa[2]
    Aaa = np.array([[-a1, 1.0], [-a2, 0.0]])
    Baa = np.array([[b1 - a1 * b0], [b2 - a2 * b0]])
    aa_sys = control.ss(Aaa, Baa, [[1.0, 0.0]], [[b0]], dt=1.0 / r.sensor_rate_hz,
                        inputs=["fsr_voltage_v"], outputs=["aa_out_v"], states=["aa_z1", "aa_z2"],
                        name="antialias")
    from ebraille_sim.estimation.registry import load_estimator
    model, _, _, _, in_slope, _, out_slope, _ = sensor_point(
        device, op.force_n, op.load_time_s, model, direction=-1.0 if op.friction == "release" else 1.0)
    model = model if model is not None else load_estimator(device.estimator.model)
    num = np.asarray(model.linear.numerator(), float)
    den = np.asarray(model.linear.denominator(), float)
    n = max(len(num), len(den))
    num = np.pad(num, (0, n - len(num))) / den[0]
    den = np.pad(den, (0, n - len(den))) / den[0]
    gain = in_slope * out_slope
    # DF2T: y = num0 x + z0 ; z_j <- num_{j+1} x + z_{j+1} - den_{j+1} y
    m = n - 1
    Ae = np.zeros((m, m))
    Be = np.zeros((m, 1))
    for j in range(m):
        Ae[j, 0] = -den[j + 1]
        if j + 1 < m:
            Ae[j, j + 1] = 1.0
        Be[j, 0] = num[j + 1] - den[j + 1] * num[0]
    Ce = np.zeros((1, m))
    Ce[0, 0] = gain
    De = np.array([[gain * num[0]]])
    names = [f"est_z{j}" for j in range(m)]
    if device.estimator.nyquist_average:
        # f = (f_raw + f_raw_prev)/2 with f_raw_prev a state
        A2 = np.zeros((m + 1, m + 1))
        A2[:m, :m] = Ae
        A2[m, :m] = Ce[0]
        B2 = np.vstack([Be, De])
        C2 = np.hstack([0.5 * Ce, [[0.5]]])
        D2 = 0.5 * De
        Ae, Be, Ce, De = A2, B2, C2, D2
        names.append("est_raw_prev_n")
    est_sys = control.ss(Ae, Be, Ce, De, dt=model.dt_s, inputs=["aa_out_v"], outputs=["force_est_n"],
                         states=names, name="estimator")
    return aa_sys, est_sys


def _ratio(device: DeviceParams, est_dt: float) -> int:
    n = device.rates.control_rate_hz * est_dt
    if abs(n - round(n)) > 1e-9 or round(n) < 1:
        raise ValueError(f"the estimator period {est_dt:g} s must be a whole number of control periods")
    if device.rates.sensor_rate_hz != device.rates.control_rate_hz:
        raise ValueError("the sampled-data model assumes the sensor rate equals the control rate")
    return int(round(n))


def sampled_front(device: DeviceParams, op: OperatingPoint) -> tuple[control.StateSpace, control.StateSpace]:
    """Control-rate model from the command to the anti-alias output, and the estimator.

    With the estimator's creep compensation the front has a second input, the estimate the
    firmware holds (:func:`compensation_model`); :func:`_lift` closes that path."""
    ct = continuous_model(device, op)
    h = 1.0 / device.rates.control_rate_hz
    dt_sys = control.c2d(ct[1, 0], h, method="zoh")
    dt_sys = control.ss(dt_sys.A, dt_sys.B, dt_sys.C, dt_sys.D, dt=h, inputs=["command_v"],
                        outputs=["fsr_voltage_inst_v"], states=list(CONTINUOUS_STATES))
    aa, est = sensor_models(device, op)
    if not device.estimator.creep_compensation:
        front = control.series(control.series(dt_sys, creep_model(device)), aa)
        front = control.ss(front.A, front.B, front.C, front.D, dt=h, inputs=["command_v"], outputs=["aa_out_v"],
                           states=list(CONTINUOUS_STATES) + CREEP_STATES + ["aa_z1", "aa_z2"], name="front")
        return front, est
    g1 = control.series(dt_sys, creep_model(device))
    comp = compensation_model(device, op)
    A1, B1, C1, D1 = (np.atleast_2d(np.asarray(m, float)) for m in (g1.A, g1.B, g1.C, g1.D))
    Ac, Bc, Cc, Dc = (np.atleast_2d(np.asarray(m, float)) for m in (comp.A, comp.B, comp.C, comp.D))
    Aa, Ba, Ca, Da = (np.atleast_2d(np.asarray(m, float)) for m in (aa.A, aa.B, aa.C, aa.D))
    n1, nc, na = A1.shape[0], Ac.shape[0], Aa.shape[0]
    bcv, bce, dcv, dce = Bc[:, [0]], Bc[:, [1]], Dc[0, 0], Dc[0, 1]
    A = np.block([[A1, np.zeros((n1, nc)), np.zeros((n1, na))],
                  [bcv @ C1, Ac, np.zeros((nc, na))],
                  [dcv * (Ba @ C1), Ba @ Cc, Aa]])
    B = np.block([[B1, np.zeros((n1, 1))],
                  [bcv @ D1, bce],
                  [dcv * (Ba @ D1), dce * Ba]])
    C = np.hstack([dcv * (Da @ C1), Da @ Cc, Ca])
    D = np.hstack([dcv * (Da @ D1), dce * Da])
    front = control.ss(A, B, C, D, dt=h, inputs=["command_v", "force_est_held_n"], outputs=["aa_out_v"],
                       states=list(CONTINUOUS_STATES) + CREEP_STATES + COMP_STATES + ["aa_z1", "aa_z2"],
                       name="front")
    return front, est


def _compensated(front: control.StateSpace) -> bool:
    return front.ninputs == 2


def _lift(A, Bu, Be, C, De, est: control.StateSpace, n: int):
    """Lift a sensor-rate model with the compensation's held-estimate input to the estimator rate.

    ``x+ = A x + Bu u + Be e``, ``y = C x + De e`` (``u`` held over the ``n`` samples, ``e``
    the estimate the compensation holds).  The sample that feeds the estimator still holds
    the previous estimate; the ``n - 1`` samples after it hold the new one.  Returns
    ``(A_L, B_L, C_L)``: states ``[x, estimator states, est_held]``, inputs ``u``, output the
    new estimate (no direct term).
    """
    Ae, Bes, Ce, Des = (np.atleast_2d(np.asarray(m, float)) for m in (est.A, est.B, est.C, est.D))
    nx, ne = A.shape[0], Ae.shape[0]
    An, Bn = lift(A, Bu, n)
    An1 = np.linalg.matrix_power(A, n - 1)
    S = np.zeros_like(A)
    Ak = np.eye(nx)
    for _ in range(n - 1):
        S += Ak
        Ak = A @ Ak
    # est_k = Des C x + Ce xe + Des De e_prev
    ex = Des @ C
    ee = Des @ De
    AL = np.zeros((nx + ne + 1, nx + ne + 1))
    AL[:nx, :nx] = An + S @ Be @ ex
    AL[:nx, nx:nx + ne] = S @ Be @ Ce
    AL[:nx, [-1]] = An1 @ Be + S @ Be @ ee
    AL[nx:nx + ne, :nx] = Bes @ C
    AL[nx:nx + ne, nx:nx + ne] = Ae
    AL[nx:nx + ne, [-1]] = Bes @ De
    AL[[-1], :nx] = ex
    AL[[-1], nx:nx + ne] = Ce
    AL[-1, -1] = ee[0, 0]
    BL = np.vstack([Bn, np.zeros((ne + 1, Bu.shape[1]))])
    CL = np.hstack([ex, Ce, ee])
    return AL, BL, CL


def lift(A: np.ndarray, B: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``(A^n, sum_{j<n} A^j B)``: ``n`` steps of ``x+ = A x + B u`` with ``u`` held."""
    An = np.eye(A.shape[0])
    Bn = np.zeros_like(B)
    for _ in range(n):
        Bn = A @ Bn + B
        An = A @ An
    return An, Bn


def linearize(device: DeviceParams = DeviceParams(), force_n: float = 1.0, *, friction: str = "press",
              finger_pos_m: float = 1e-3, load_time_s: float = 20.0, return_point: bool = False):
    """Small-signal plant from the command (V) to the estimated force (N).

    A discrete-time ``control.StateSpace`` at the estimator's period (0.01 s): the input
    is the command held over one estimator period, the output the estimate produced at
    the end of it (see the module docstring for the sampled-data method).  States, in
    order: :data:`CONTINUOUS_STATES`, :data:`CREEP_STATES`, ``aa_z1``, ``aa_z2``, ``est_z0...``,
    ``est_raw_prev_n``; all are deviations from the operating point.

    Parameters
    ----------
    device : DeviceParams
    force_n : float
        Operating contact force, N (relaxed equilibrium).
    friction : {"press", "release", "none"}
        Sliding direction for the friction linearisation.
    finger_pos_m : float
        Pulp surface position (the scenario's gap), m; it only shifts positions.
    load_time_s : float
        Time the operating force has been held on a recovered FSR film, s: it sets the creep
        states and the divider slope at the operating point; the creep's small-signal
        dynamics are in the model (:func:`creep_model`).
    return_point : bool
        Also return the :class:`OperatingPoint`.

    Returns
    -------
    StateSpace or (StateSpace, OperatingPoint)
    """
    op = operating_point(device, force_n, friction=friction, finger_pos_m=finger_pos_m,
                         load_time_s=load_time_s)
    front, est = sampled_front(device, op)
    n = _ratio(device, est.dt)
    if _compensated(front):
        A, B, C, D = (np.atleast_2d(np.asarray(m, float)) for m in (front.A, front.B, front.C, front.D))
        AL, BL, CL = _lift(A, B[:, [0]], B[:, [1]], C, D[:, [1]], est, n)
        plant = control.ss(AL, BL, CL, np.zeros((1, 1)), dt=est.dt, inputs=["command_v"], outputs=["force_est_n"],
                           states=front.state_labels + est.state_labels + [ESTIMATE_HELD_STATE], name="plant")
        return (plant, op) if return_point else plant
    An, Bn = lift(front.A, front.B, n)
    lifted = control.ss(An, Bn, front.C, np.zeros((1, 1)), dt=est.dt, inputs=["command_v"],
                        outputs=["aa_out_v"], states=front.state_labels)
    plant = control.series(lifted, est)
    plant = control.ss(plant.A, plant.B, plant.C, plant.D, dt=est.dt, inputs=["command_v"],
                       outputs=["force_est_n"], states=front.state_labels + est.state_labels,
                       name="plant")
    return (plant, op) if return_point else plant


def pid_statespace(config, dt_s: float) -> control.StateSpace:
    """The linear part of :class:`controllers.pid.PID` (no saturation) at the step ``dt_s``.

    Inputs ``setpoint_n`` and ``force_est_n``; output ``command_v``; states
    ``integrator_v`` and ``derivative_v``.  Exactly the recursions of :mod:`controllers.pid`:
    forward-Euler integral on ``r - y``, backward-difference filtered derivative on
    ``c r - y``, proportional on ``b r - y``.
    """
    kp, ki, kd = config.kp_v_per_n, config.ki_v_per_ns, config.kd_vs_per_n
    tf, b, c, h = config.derivative_filter_s, config.setpoint_weight_p, config.setpoint_weight_d, dt_s
    alpha = tf / (tf + h)
    beta = kd / (tf + h)
    A = np.diag([1.0, alpha])
    B = np.array([[ki * h, -ki * h], [(alpha - 1.0) * beta * c, -(alpha - 1.0) * beta]])
    C = np.array([[1.0, 1.0]])
    D = np.array([[kp * b + beta * c, -(kp + beta)]])
    return control.ss(A, B, C, D, dt=h, inputs=["setpoint_n", "force_est_n"], outputs=["command_v"],
                      states=["integrator_v", "derivative_v"], name="pid")


def loop_models(device: DeviceParams, force_n: float, controller, *, friction: str = "press",
                op: OperatingPoint | None = None, front=None):
    """Exact sampled-data loop at the estimator rate.

    ``controller`` is a two-input (setpoint, estimate) ``StateSpace`` at the control rate
    (e.g. :func:`pid_statespace`), a :class:`~controllers.pid.PIDConfig`, a controller
    object: a :class:`~controllers.pid.PID` (its config at ``force_n``, :meth:`~controllers.pid.PIDConfig.at`), a scheduled PID (its
    fixed equivalent at ``force_n``, ``pid_config_at``) or one with a ``statespace()``
    method (:mod:`controllers.lqg`), or a two-input ``StateSpace`` already at the
    estimator rate.  Anything else is a one-line ``TypeError``.

    Returns
    -------
    loop : StateSpace
        Loop transfer ``L`` (estimate in, estimate out, negative feedback), at the
        estimator rate.
    closed : StateSpace
        Setpoint to estimated force, closed loop.
    """
    from controllers.pid import PIDConfig
    if front is None:
        if op is None:
            op = operating_point(device, force_n, friction=friction)
        front = sampled_front(device, op)
    fr, est = front
    n = _ratio(device, est.dt)
    h = fr.dt
    if isinstance(getattr(controller, "config", None), PIDConfig):
        controller = controller.config
    elif hasattr(controller, "pid_config_at"):
        controller = controller.pid_config_at(force_n)
    elif hasattr(controller, "statespace") and callable(controller.statespace):
        controller = controller.statespace()
    if isinstance(controller, PIDConfig):
        controller = controller.at(force_n)
    if not isinstance(controller, PIDConfig) and not all(hasattr(controller, m) for m in "ABCD"):
        raise TypeError(f"cannot analyse a controller of type {type(controller).__name__}: give a PIDConfig, "
                        "a PID, a scheduled PID, an object with statespace() or a two-input StateSpace")
    if isinstance(controller, PIDConfig):
        controller = pid_statespace(controller, h)
    Ac, Bc, Cc, Dc = (np.atleast_2d(np.asarray(m, float)) for m in
                      (controller.A, controller.B, controller.C, controller.D))
    nx, nc = fr.A.shape[0], Ac.shape[0]
    if _compensated(fr):
        Af, Bf, Cf, Df = (np.atleast_2d(np.asarray(m, float)) for m in (fr.A, fr.B, fr.C, fr.D))
        bu, be = Bf[:, [0]], Bf[:, [1]]
        if math.isclose(controller.dt, h):
            AJ = np.block([[Af, bu @ Cc], [np.zeros((nc, nx)), Ac]])
            BJ = np.vstack([bu @ Dc, Bc])
            BE = np.vstack([be, np.zeros((nc, 1))])
            CJ = np.hstack([Cf, np.zeros((1, nc))])
            A, B, C = _lift(AJ, BJ, BE, CJ, Df[:, [1]], est, n)
        elif math.isclose(controller.dt, est.dt):
            AL, BL, CL = _lift(Af, bu, be, Cf, Df[:, [1]], est, n)
            q = control.series(control.ss(Ac, Bc, Cc, Dc, dt=est.dt), control.ss(AL, BL, CL, [[0.0]], dt=est.dt))
            A, B, C = q.A, q.B, q.C
            if np.any(np.abs(q.D) > 0):
                raise ValueError("the sampled loop must be strictly proper")
        else:
            raise ValueError(f"controller dt {controller.dt} must equal the control period {h} or the "
                             f"estimator period {est.dt}")
        loop = control.ss(A, -B[:, [1]], C, np.zeros((1, 1)), dt=est.dt, inputs=["e"], outputs=["force_est_n"])
        closed = control.ss(A + B[:, [1]] @ C, B[:, [0]], C, np.zeros((1, 1)), dt=est.dt,
                            inputs=["setpoint_n"], outputs=["force_est_n"])
        return loop, closed
    if math.isclose(controller.dt, h):
        # controller and plant lifted together over n control periods
        AJ = np.block([[fr.A, fr.B @ Cc], [np.zeros((nc, nx)), Ac]])
        BJ = np.vstack([fr.B @ Dc, Bc])
        An, Bn = lift(AJ, BJ, n)
        CJ = np.hstack([fr.C, np.zeros((1, nc))])
        q = control.ss(An, Bn, CJ, np.zeros((1, 2)), dt=est.dt)
        q = control.series(q, est)
    elif math.isclose(controller.dt, est.dt):
        An, Bn = lift(fr.A, fr.B, n)
        p = control.series(control.ss(An, Bn, fr.C, np.zeros((1, 1)), dt=est.dt), est)
        # controller then plant
        q = control.series(control.ss(Ac, Bc, Cc, Dc, dt=est.dt), p)
    else:
        raise ValueError(f"controller dt {controller.dt} must equal the control period {h} or the "
                         f"estimator period {est.dt}")
    A, B, C, D = q.A, q.B, q.C, q.D
    if np.any(np.abs(D) > 0):
        raise ValueError("the sampled loop must be strictly proper")
    loop = control.ss(A, -B[:, [1]], C, np.zeros((1, 1)), dt=est.dt, inputs=["e"], outputs=["force_est_n"])
    closed = control.ss(A + B[:, [1]] @ C, B[:, [0]], C, np.zeros((1, 1)), dt=est.dt,
                        inputs=["setpoint_n"], outputs=["force_est_n"])
    return loop, closed
