"""Figures of docs/model.md: python studies/model/make_model_figures.py (writes the PNGs into
docs/figures/model/ and summary.json into studies/model/)."""
from __future__ import annotations

import dataclasses
import json
import pathlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import ebraille_sim  # noqa: E402
from ebraille_sim.plant import kernel  # noqa: E402
from ebraille_sim.estimation.calibration import static_error_table  # noqa: E402
from ebraille_sim.physics.fingertip import relaxation_function  # noqa: E402
from ebraille_sim.plant.layout import N_INPUT, S, U  # noqa: E402
from ebraille_sim.plant.lumped import Plant, initial_state, pack_params  # noqa: E402
from ebraille_sim.estimation.paper_models import paper_model  # noqa: E402
from ebraille_sim.physics.params import (FINGERS, CircuitParams, DeviceParams, DriveTrainParams, FSRParams,  # noqa: E402
                                 RateParams)
from ebraille_sim.tools.report import plot_force  # noqa: E402

HERE = pathlib.Path(__file__).resolve().parent
OUT = HERE
FIG = HERE.parents[1] / "docs" / "figures" / "model"


def fig_scenarios(summary):
    for name, dur in (("steady_90wpm", 10.0), ("setpoint_steps", None), ("contact_onset", None)):
        res = ebraille_sim.run_scenario(name, duration_s=dur)
        plot_force(res, FIG / f"{name}.png")
        summary[name] = res.metrics


def fig_relaxation():
    stiff = DriveTrainParams(mesh_stiffness_n_per_m=3e6, backlash_m=0.0, travel_max_m=0.01)
    dev = DeviceParams(drivetrain=stiff, rates=RateParams(1000, 1000, 200_000))
    fig, ax = plt.subplots(figsize=(7, 4))
    for name in ("soft", "nominal", "stiff"):
        d = dataclasses.replace(dev, finger=FINGERS[name])
        plant = Plant.from_devices([d], seeds=[0], board_pos_m=2.0e-3)
        plant.set_input("motor_jammed", 1.0)
        plant.set_finger(0.6e-3)
        t, f = [], []
        for k in range(4000):
            plant.advance(0.0)
            t.append((k + 1) * 1e-3)
            f.append(plant.contact_force_n[0])
        fe = FINGERS[name].elastic_force_n(1.4e-3)
        ax.semilogx(t, f, label=f"{name}: simulated")
        ax.semilogx(t, fe * relaxation_function(np.array(t), FINGERS[name]), "k:", lw=1)
    ax.set_xlabel("time after a 1.4 mm indentation step (s)")
    ax.set_ylabel("contact force (N)")
    ax.set_title("Pulp relaxation (QLV, 4 ms / 70 ms / 1.4 s); dotted: Fe(d) G(t)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(FIG / "relaxation.png", dpi=110)
    plt.close(fig)


def _sensor(fsr, circuit):
    dev = DeviceParams(fsr=fsr, circuit=circuit)
    p = pack_params(dev, 0)
    s = initial_state(dev, p)
    u = np.zeros(N_INPUT)
    u[U["driver_supply_v"]] = 6.0
    return s, p, u


def fig_fsr(summary):
    fsr = FSRParams(noise_v_rms=0.0)
    c = CircuitParams()
    s, p, u = _sensor(fsr, c)
    up = np.linspace(0.0, 3.0, 151)
    down = up[::-1]
    v_up, v_down, e_up, e_down = [], [], [], []
    for f in up:
        kernel.advance_sensor_only(s, p, u, float(f), 200)
        v_up.append(s[S["fsr_voltage_v"]])
    kernel.advance_sensor_only(s, p, u, 3.0, 30000)
    for f in down:
        kernel.advance_sensor_only(s, p, u, float(f), 200)
        v_down.append(s[S["fsr_voltage_v"]])
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4))
    a1.plot(up, v_up, label="loading")
    a1.plot(down, v_down, label="unloading")
    a1.set_xlabel("force (N)")
    a1.set_ylabel(f"divider voltage (V), R2 = {c.r2_ohm:.0f} ohm")
    a1.set_title("FSR 402 forward model: hysteresis loop (10 %)")
    a1.legend()
    rows = static_error_table(paper_model("wiener", 5), FSRParams(), c,
                              forces_n=tuple(np.round(np.linspace(0.2, 3.0, 29), 3)))
    ff = [r["force_n"] for r in rows]
    for key, lab in (("rel_error_at_1s", "hold 1 s"), ("rel_error_at_60s", "hold 60 s"),
                     ("rel_error_at_1800s", "hold 30 min")):
        a2.plot(ff, [100 * r[key] for r in rows], label=lab)
    a2.axhspan(-10, 10, color="0.92", zorder=0)
    a2.set_xlabel("held force (N)")
    a2.set_ylabel("steady estimate error (%)")
    a2.set_title("Paper's Wiener estimator on the calibrated divider")
    a2.legend()
    fig.tight_layout()
    fig.savefig(FIG / "fsr_and_estimator.png", dpi=110)
    plt.close(fig)
    summary["static_error_pct"] = {f"{r['force_n']:.1f}": round(100 * r["rel_error_at_60s"], 1)
                                   for r in rows if r["force_n"] in (0.2, 0.5, 1.0, 1.5, 2.0, 3.0)}
    wiener = paper_model("wiener", 5)
    hyst = {}
    for f in (0.5, 1.0, 2.0):
        k_up, k_down = int(np.argmin(np.abs(up - f))), int(np.argmin(np.abs(down - f)))
        e_up = float(wiener.steady_state(v_up[k_up] - v_up[0]))
        e_down = float(wiener.steady_state(v_down[k_down] - v_up[0]))
        hyst[f"{f:.1f}"] = round(100 * (e_down - e_up) / f, 1)
    summary["hysteresis_loop_estimate_gap_pct"] = hyst
    for key in ("rel_error_at_1s", "rel_error_at_1800s"):
        summary[f"static_error_pct_{key[13:]}"] = {f"{r['force_n']:.1f}": round(100 * r[key], 1)
                                                   for r in rows if r["force_n"] in (0.5, 1.0, 2.0)}


def fig_drive(summary):
    dt = DriveTrainParams(travel_max_m=0.05)
    plant = Plant.from_devices([DeviceParams(drivetrain=dt)], seeds=[0])
    plant.set_finger(1.0)
    t, v, i = [], [], []
    for k in range(100):
        plant.advance(6.0 if k >= 5 else 0.0)
        t.append((k + 1) * 1e-3)
        v.append(plant.state[0][S["board_vel_m_per_s"]] * 1e3)
        i.append(plant.motor_current_a[0] * 1e3)
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(t, v, label="board speed (mm/s)")
    ax.plot(t, i, label="motor current (mA)")
    ax.set_xlabel("time (s)")
    ax.set_title("6 V step, no contact: break-away, 6.5 ms rise, friction-limited speed")
    ax.legend()
    fig.tight_layout()
    fig.savefig(FIG / "drive_step.png", dpi=110)
    plt.close(fig)
    summary["free_speed_mm_per_s_at_6v"] = round(v[-1], 2)


def main():
    FIG.mkdir(parents=True, exist_ok=True)
    summary = {}
    fig_scenarios(summary)
    fig_relaxation()
    fig_fsr(summary)
    fig_drive(summary)
    (OUT / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    print(json.dumps(summary, indent=2))


if __name__ == "__main__":
    main()
