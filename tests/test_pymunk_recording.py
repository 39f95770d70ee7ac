"""The recorder of the pymunk plant (ebraille_sim.plant.pymunk.recording): an explicit argument
that takes snapshots at its interval and changes nothing in the run."""
from __future__ import annotations

import numpy as np
import pytest

from ebraille_sim.physics.params import DeviceParams
from ebraille_sim.plant.pymunk.plant import PymunkPlant
from ebraille_sim.plant.pymunk.recording import Recorder
from ebraille_sim.scenarios.runner import run_scenario


def test_recording_a_run_changes_nothing_and_takes_a_frame_every_interval():
    plain = run_scenario("contact_onset", backend="pymunk", duration_s=0.5, seed=4)
    rec = Recorder(every_s=0.1)
    recorded = run_scenario("contact_onset", backend="pymunk", duration_s=0.5, seed=4, recorder=rec)
    for col in ("force_true_n", "force_est_n", "command_v", "board_pos_m"):
        assert np.array_equal(plain.trace[col], recorded.trace[col]), col
    t = [f["t_s"] for f in rec.frames]
    np.testing.assert_allclose(t, [0.0, 0.1, 0.2, 0.3, 0.4, 0.5], atol=1e-12)
    # the frame at the end of the run is the state the trace ends on
    assert rec.frames[-1]["force_true_n"] == recorded.trace["force_true_n"][-1]
    assert rec.frames[-1]["board_y_m"] == pytest.approx(recorded.trace["board_pos_m"][-1], abs=1e-15)


def test_a_recorder_records_only_the_plant_it_is_handed_to():
    rec = Recorder(every_s=0.001, device_index=1)
    watched = PymunkPlant.from_devices([DeviceParams(), DeviceParams()], seeds=[1, 2], recorder=rec)
    other = PymunkPlant.from_devices([DeviceParams()], seeds=[1])
    assert other.recorder is None and watched.recorder is rec
    for _ in range(3):
        other.advance(1.0)
    assert len(rec.frames) == 1                   # the snapshot taken when the plant was built
    rec.after_step(other)                         # another plant handed in by hand is ignored
    assert len(rec.frames) == 1
    watched.advance(np.array([0.0, 2.0]))
    assert len(rec.frames) == 2 and rec.frames[1]["t_s"] == pytest.approx(0.001)
    assert rec.frames[1]["current_a"] == watched.mechanisms[1].current_a != watched.mechanisms[0].current_a


@pytest.mark.parametrize("kwargs, message", [
    ({"every_s": 0.0}, "recording interval must be a positive number of seconds"),
    ({"every_s": float("nan")}, "recording interval"),
    ({"every_s": "fast"}, "recording interval"),
    ({"device_index": -1}, "device_index must be a whole number >= 0"),
    ({"device_index": 1.5}, "device_index"),
])
def test_bad_recorder_arguments_give_one_line_errors(kwargs, message):
    with pytest.raises(ValueError, match=message) as exc:
        Recorder(**kwargs)
    assert "\n" not in str(exc.value)


def test_a_recorder_needs_the_pymunk_backend_and_an_existing_device():
    with pytest.raises(ValueError, match="a recorder records the pymunk mechanism; use backend='pymunk'"):
        run_scenario("contact_onset", duration_s=0.1, recorder=Recorder())
    with pytest.raises(ValueError, match="device_index 1 is out of range for a plant of 1 device"):
        PymunkPlant.from_devices([DeviceParams()], seeds=[1], recorder=Recorder(device_index=1))
