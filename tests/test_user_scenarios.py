"""Scenarios a user writes: mixes of a soft reader, a non-nominal FSR unit, jittered reading with
word pauses, tremor with pressing, a warming FSR and a setpoint change, run with the defaults
(no controller or firmware named)."""
from __future__ import annotations

import pathlib
import tomllib

import pytest

from ebraille_sim.physics.params import FINGERS, FSRS
from ebraille_sim.scenarios.spec import DEFAULT_DESIGN
from ebraille_sim.scenarios.runner import run_scenario
from ebraille_sim.scenarios.spec import load_scenario, parse_scenario

MIXED = pathlib.Path(__file__).resolve().parents[1] / "scenarios" / "mixed_reader.toml"


def _variant(**changes) -> dict:
    """The shipped mixed scenario with ``section__key`` values replaced (a table replaces the key's table)."""
    d = tomllib.loads(MIXED.read_text(encoding="utf-8"))
    for k, v in changes.items():
        section, key = k.split("__")
        d.setdefault(section, {})[key] = v
    return d


def test_the_mixed_scenario_mixes_what_it_says():
    spec = load_scenario(str(MIXED))
    assert spec.controller.name == DEFAULT_DESIGN and spec.calibrated
    assert spec.device.finger == FINGERS["soft"]
    assert spec.device.fsr == FSRS["high_k"]
    assert spec.reading.wpm == 100 and spec.reading.jitter_fraction > 0 and spec.reading.word_pause_s > 0
    assert set(spec.sections["disturbances"]) >= {"pressing", "tremor", "fsr_temperature"}
    assert spec.setpoint.steps == ((10.0, 1.3),)


@pytest.mark.parametrize("seed", [41, 7])
def test_the_defaults_hold_the_mixed_scenario(seed):
    """A soft reader with a calibrated high-k unit, 100 wpm with jitter and pauses, tremor and
    pressing, a warming film and a step from 1.0 to 1.3 N: at least 0.8 in band (measured
    0.884 at seed 41 and 0.875 at seed 7; with the unit left uncalibrated it held 0.05)."""
    r = run_scenario(str(MIXED), seed=seed)
    assert r.supervisor["fault"] is None
    assert r.metrics["in_band_fraction"] >= 0.8
    assert r.metrics["peak_force_n"] < 2.0


VARIANTS = {
    # a stiff reader with a low-k unit, a cooling film and a step down
    "stiff_low_k_down": dict(device__finger="stiff", device__fsr="low_k", reading__wpm=80, setpoint__force_n=1.2,
                             setpoint__steps=[[8.0, 0.8]],
                             disturbances__fsr_temperature={"start_c": 31.0, "skin_c": 20.0, "tau_s": 60.0}),
    # the nominal pulp at 110 wpm stepping up to 1.5 N
    "nominal_up_to_1.5": dict(device__finger="nominal", reading__wpm=110, setpoint__steps=[[6.0, 1.5]]),
    # the soft reader with a low-k unit and a stronger, slower tremor
    "soft_low_k_tremor": dict(device__fsr="low_k",
                              disturbances__tremor={"rms_m": 20e-6, "band_hz": [6.0, 10.0], "transmission": 1.0}),
    # the soft reader at 120 wpm pressing twice as hard
    "soft_120wpm_pressing": dict(reading__wpm=120, disturbances__pressing={"rms_m": 0.1e-3}),
}


@pytest.mark.parametrize("name", sorted(VARIANTS))
def test_the_defaults_hold_other_mixes(name):
    """Other mixes of the same ingredients (none of them tuned on): at least 0.7 in band with
    no latch (measured 0.716-0.882; the stiff reader with the low-k unit, a cooling film and a
    step down to 0.8 N is the lowest)."""
    d = _variant(**VARIANTS[name])
    d["name"] = f"mixed_{name}"
    r = run_scenario(parse_scenario(d, source=name), seed=41)
    assert r.supervisor["fault"] is None
    assert r.metrics["in_band_fraction"] >= 0.7
    assert r.metrics["peak_force_n"] < 2.5
