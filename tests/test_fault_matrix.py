"""The fault matrix: every injected fault, alone and in pairs, in every phase, with the supervisor on.

A cell is a scenario built here: a reader (nominal, or drawn from the population), a reading
rate (60 or 120 wpm) with tremor, a phase (``onset``: the fault starts before first contact;
``steady``: during reading at 1 N; ``step``: as the setpoint steps to 3 N, which the
supervisor clips to 2.7 N) and one or two faults.  Contract in every cell: the true force at
the finger stays at or below 3.5 N (the supervisor's ``safe_force_n``).

``FAULTS`` also holds the sensor's plausible lies: a reading fixed at 0.2 V or 0.45 V (a
stuck code in the force range), and a high-k FSR unit on a device calibrated for the nominal
unit (it under-reads).  The fast test runs the single faults on the nominal reader at
60 wpm; the slow one the pairs, 120 wpm and the population.  ``studies/safety/make_safety_table.py``
writes the table of docs/safety.md from :func:`run_cell`.
"""
from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest

from ebraille_sim.physics.params import FSRS
from controllers.designs import designs
from ebraille_sim.scenarios.population import device_from_variates, sample_devices
from ebraille_sim.scenarios.runner import run_scenario
from ebraille_sim.scenarios.spec import parse_scenario

SAFE_N = 3.5
DURATION_S = 4.0
READ_S = 1.0
PHASE_START_S = {"onset": 0.02, "steady": 2.0, "step": 2.0}
STEP_N = 3.0

FAULTS = {
    "fsr_open": {"kind": "fsr_open"},
    "fsr_short": {"kind": "fsr_short"},
    "fsr_stuck": {"kind": "fsr_stuck"},
    "fsr_at_0.2V": {"kind": "fsr_value", "value_v": 0.2},
    "fsr_at_0.45V": {"kind": "fsr_value", "value_v": 0.45},
    "fsr_at_1.0V": {"kind": "fsr_value", "value_v": 1.0},
    "high_k_unit": None,
    "motor_stall": {"kind": "motor_stall", "duration_s": 1.0},
    "controller_nan": {"kind": "controller_nan", "duration_s": 0.3},
    "finger_withdrawn": {"kind": "finger_withdrawn", "duration_s": 0.6},
}
"""Fault names and their ``[[faults]]`` entry (``None``: a device fault, the high-k unit)."""


def cell_spec(faults, phase, wpm=60, device=None):
    """The scenario of one cell: ``faults`` (names of :data:`FAULTS`) injected in ``phase``."""
    t0 = PHASE_START_S[phase]
    entries = []
    for name in faults:
        e = FAULTS[name]
        if e is not None:
            entries.append({**e, "start_s": t0})
    data = {
        "name": "cell", "description": "fault matrix cell", "seed": 5, "duration_s": DURATION_S,
        "reading": {"passage": "default", "wpm": wpm, "start_s": READ_S},
        "setpoint": {"force_n": 1.0, "band_fraction": 0.1},
        "finger": {"gap_m": 0.001},
        "disturbances": {"tremor": {"rms_m": 15e-6, "band_hz": [8.0, 12.0], "transmission": 1.0}},
        "supervisor": {},
    }
    if phase == "step":
        data["setpoint"]["steps"] = [[t0, STEP_N]]
    if entries:
        data["faults"] = entries
    spec = parse_scenario(data)
    dev = device if device is not None else spec.device
    if "high_k_unit" in faults:
        dev = dataclasses.replace(dev, fsr=FSRS["high_k"])
    return dataclasses.replace(spec, device=dev)


def run_cell(faults, phase, wpm=60, device=None, controller=None) -> dict:
    """Peak true force and the supervisor's first fault or freeze after the fault starts
    (``controller``: a design or controller instead of the scenario's default)."""
    spec = cell_spec(faults, phase, wpm, device)
    res = run_scenario(spec, controller=controller)
    tr = res.trace
    t0 = PHASE_START_S[phase]
    return {"peak_n": float(tr["force_true_n"].max()),
            "above_s": float(np.sum(tr["force_true_n"] > SAFE_N) * (tr["t_s"][1] - tr["t_s"][0])),
            "t0_s": t0, "trace": tr}


def detection(tr, t0):
    """Time from ``t0`` to the first period in which the supervisor stops pushing (retract or hold)."""
    late = (tr["t_s"] > t0 + 0.01) & (tr["command_v"] <= -1.9)
    return float(tr["t_s"][late][0] - t0) if late.any() else None


SINGLE = [(f,) for f in FAULTS]
PAIRS = list(itertools.combinations(FAULTS, 2))
PHASES = list(PHASE_START_S)


@pytest.mark.parametrize("phase", PHASES)
def test_single_faults_keep_the_true_force_safe(phase):
    peaks = {f[0]: run_cell(f, phase)["peak_n"] for f in SINGLE}
    assert max(peaks.values()) <= SAFE_N, peaks


@pytest.mark.parametrize("case,phase", [(("fsr_at_0.2V",), "steady"), (("fsr_at_0.45V",), "steady"),
                                        (("fsr_stuck",), "onset"), (("fsr_open",), "onset"),
                                        (("fsr_at_0.45V",), "onset"), (("high_k_unit",), "step")])
def test_the_sensor_lies_that_went_unseen_are_bounded(case, phase):
    r = run_cell(case, phase)
    assert r["peak_n"] <= SAFE_N and r["above_s"] == 0.0


def test_a_sensor_reading_a_fixed_plausible_value_is_detected():
    """A reading stuck at 0.45 V (plausible, about 1 N) is detected within 1.8 s in the run with
    seed 20.  How soon depends on the tremor's and the noise's realisation: over the 60 seeds
    100-159 the supervisor stops pushing within 1.8 s in 16 and within the run's 2 s in 20 (24
    under the random streams before the draws' compiled home, 16 within 1.8 s); the peak stays
    below 3.5 N in every one (:func:`test_the_sensor_lies_that_went_unseen_are_bounded`)."""
    spec = dataclasses.replace(cell_spec(("fsr_at_0.45V",), "steady"), seed=20)
    d = detection(run_scenario(spec).trace, PHASE_START_S["steady"])
    assert d is not None and d < 1.8


def test_without_the_supervisor_the_same_lie_presses_too_hard():
    spec = cell_spec(("fsr_at_0.45V",), "steady")
    assert run_scenario(spec, supervised=False).trace["force_true_n"].max() > SAFE_N


@pytest.mark.slow
@pytest.mark.parametrize("phase", PHASES)
def test_fault_pairs_at_120_wpm_keep_the_true_force_safe(phase):
    peaks = {f: run_cell(f, phase, wpm=120)["peak_n"] for f in PAIRS}
    worst = max(peaks, key=peaks.get)
    assert peaks[worst] <= SAFE_N, (worst, peaks[worst])


READERS = [
    ([0.6309070111049604, 0.9053785513265734, 0.2845631059499206, 0.9756481966034417, 0.6648342158642109,
      0.371815183190622, 0.28877913786045795, 0.45546846404368113, 0.21272123191393222, 0.4590267488955505,
      0.6626072517880793, 0.0241537547839894, 0.973532616053914,
      0.5, 0.5, 0.5],
     [-1.051005359417551, 0.09108591438931732, 2.5366307364231417]),
    ([0.19957401872841762, 0.32603595732411605, 0.11240680957405147, 0.7363668473888518, 0.20032017212027786,
      0.1804417246536122, 0.1776100784049034, 0.569809602677544, 0.6546569944210363, 0.4563485687795654,
      0.3578862990394126, 0.8435043187800519, 0.043724765510672725,
      0.5, 0.5, 0.5],
     [0.11241496610089803, 0.24360268872982657, -1.334492781964075]),
    ([0.023402716185831007, 0.7645154008957528, 0.8139231683609323, 0.2743114436378842, 0.42852267834983815,
      0.18130802362258402, 0.2739301086494521, 0.1418180892882247, 0.5528929585394734, 0.5047275325945261,
      0.8678299202095278, 0.032626842295732095, 0.9606697817959119,
      0.5, 0.5, 0.5],
     [0.3501686646774418, 1.7178566145832805, 1.4010236710208424]),
]
"""The variates (:func:`ebraille_sim.scenarios.population.device_from_variates`) of the three
drawn readers the matrix runs over: ``sample_devices(13, 3)`` under the streams of their time.
Over other readers the finger withdrawn at the onset pressed harder than 3.5 N while the board's
approach ran on beyond the design gap (8 of 120 onset cells of 60 readers of seed 777 at 60 and
120 wpm, worst 4.11 N); with the search beyond the design gap at the re-approach speed
(``search_gap_m``) none does (worst 2.62 N), and
:data:`WITHDRAWN_READER` pins one of them."""

WITHDRAWN_READER = (
    [0.9875053380731504, 0.7804184456359456, 0.502702237334992, 0.8453322837791956, 0.2868284256904131,
     0.728969758612706, 0.2308806312025159, 0.2051358454019513, 0.39461956917293706, 0.5337029652673523,
     0.7436115029476208, 0.4815846432780435, 0.5400862664822943, 0.645485152329661, 0.29648545502476675,
     0.5472848147027809],
    [1.0475460285529972, 0.1043592333774521, -1.4474962556950697])
"""Variates of reader 4 of ``sample_devices(2024, 40)`` (a stiff pulp, b = 519 N/m): its finger
withdrawn at the onset returned onto a board 3.5 mm out and pressed 4.20 N before the search
beyond the design gap, 2.72 N with it."""


def test_a_finger_lifted_at_the_onset_returns_onto_a_board_that_did_not_run_on():
    dev = device_from_variates(*WITHDRAWN_READER)
    r = run_cell(("finger_withdrawn",), "onset", device=dev)
    tr = r["trace"]
    assert r["peak_n"] <= SAFE_N                             # 4.20 N while the approach ran on
    late = tr["t_s"] > DURATION_S - 1.0
    assert abs(np.median(tr["force_true_n"][late]) - 1.0) < 0.1   # and the reading goes on at 1 N


@pytest.mark.parametrize("design", sorted(designs()))
def test_the_soft_start_keeps_every_design_within_the_bound_where_the_resume_pressed_the_lifted_finger(design):
    # drawn readers 1, 6 and 11 of seed 9090 reached 4.35, 4.48 and 5.40 N with dob_hold_1khz while
    # the search's first contact resumed its integrator at 0 V instead of starting it softly
    devs = sample_devices(9090, 12)
    for k in (1, 6, 11):
        peak = run_cell(("finger_withdrawn",), "onset", wpm=(60, 120)[k % 2], device=devs[k],
                        controller=design)["peak_n"]
        assert peak <= SAFE_N, (design, k, peak)


@pytest.mark.slow
@pytest.mark.parametrize("k", range(3))
def test_single_faults_over_the_population(k):
    dev = device_from_variates(*READERS[k])
    peaks = {(f, p): run_cell(f, p, wpm=(60, 120)[k % 2], device=dev)["peak_n"] for f in SINGLE for p in PHASES}
    worst = max(peaks, key=peaks.get)
    assert peaks[worst] <= SAFE_N, (worst, peaks[worst])
