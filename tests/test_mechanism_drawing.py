"""Pictures and animations of the pymunk mechanism (ebraille_sim.tools.mechanism_drawing)."""
from __future__ import annotations

import builtins

import numpy as np
import pytest

from ebraille_sim.physics.params import DeviceParams
from ebraille_sim.plant.pymunk.plant import PymunkPlant
from ebraille_sim.tools.mechanism_drawing import draw_mechanism, draw_snapshot, write_animation

def test_picture_is_an_rgb_array_that_follows_the_mechanism(tmp_path):
    plant = PymunkPlant.from_devices([DeviceParams()], seeds=[1])
    plant.set_finger(1e-3)
    img0 = draw_mechanism(plant)
    for _ in range(300):
        plant.advance(3.0)
    img1 = draw_mechanism(plant)
    assert img0.shape == (360, 480, 3) and img0.dtype == np.uint8
    assert np.abs(img0.astype(int) - img1.astype(int)).sum() > 1000
    out = write_animation([plant.snapshot(), plant.snapshot()], tmp_path / "m.gif", fps=10)
    assert out.exists() and out.stat().st_size > 0
    assert draw_snapshot(plant.snapshot(), size_px=(320, 240)).shape == (240, 320, 3)

def test_without_pillow_the_animation_is_numbered_png_frames(tmp_path, monkeypatch):
    """Without Pillow the frames go to a folder named after the GIF, earlier frames removed."""
    real_import = builtins.__import__

    def no_pil(name, *args, **kwargs):
        if name == "PIL" or name.startswith("PIL."):
            raise ModuleNotFoundError("No module named 'PIL'")
        return real_import(name, *args, **kwargs)
    plant = PymunkPlant.from_devices([DeviceParams()], seeds=[1])
    folder = tmp_path / "anim"
    folder.mkdir()
    (folder / "frame_00007.png").write_bytes(b"stale")
    monkeypatch.setattr(builtins, "__import__", no_pil)
    done = []
    out = write_animation([plant.snapshot()] * 3, tmp_path / "anim.gif", size_px=(160, 120),
                          progress=lambda k, n: done.append((k, n)))
    assert out == folder
    assert sorted(p.name for p in folder.iterdir()) == ["frame_00000.png", "frame_00001.png", "frame_00002.png"]
    assert done == [(1, 3), (2, 3), (3, 3)]
    with pytest.raises(ValueError, match="no frames to animate"):
        write_animation([], tmp_path / "none.gif")
