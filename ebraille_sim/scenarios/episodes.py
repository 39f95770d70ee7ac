"""A distribution of reading episodes whose draws are scenario specifications.

:class:`EpisodeDistribution` holds the ranges of a training distribution (passage,
excerpt, reading rate, setpoint levels and step times, finger gap, disturbance sizes,
supply sag or battery state, device population); :meth:`EpisodeDistribution.draw` turns
one ``SeedSequence`` into a :class:`~ebraille_sim.scenarios.spec.ScenarioSpec`: a
``[reading]`` section (the excerpt as inline text), a ``[setpoint]`` section with steps,
a ``[finger]`` gap, a ``[disturbances]`` section with the scenario models
(:mod:`ebraille_sim.scenarios.disturbances`: band-limited ``tremor``, slow ``pressing``
excursions, a Li-ion ``battery``) and the drawn device.  Arrays are made from the spec by
:func:`ebraille_sim.scenarios.inputs.build_run_inputs`, the function the scenario runner
uses, so an episode and a scenario run of the same spec see the same inputs.

Seeds: every random number of an episode comes from one compiled call on its seed's key
(:func:`ebraille_sim.scenarios.draws.episode_numbers`).  The device streams give the device
(:func:`~ebraille_sim.scenarios.population.device_from_variates`: the seed's reader is the
device :func:`~ebraille_sim.scenarios.population.sample_device` draws from the same seed in a
population sweep); the episode stream gives, always all of them, the run seed (the spec's
``seed``: sensor noise and disturbance realisations) and one uniform variate per drawn scalar
(passage, excerpt start, rate, number of setpoint levels, gap, tremor, drift, battery or not,
state of charge, sag; then ``max_setpoint_levels`` levels and one fewer step times).  Every
drawn value is a fixed function of its own variate, so fixing a component (``fixed`` of
:meth:`draw`) or changing one range shifts no other draw.

==============  ===========================================================  ==========
component       draw                                                         source
==============  ===========================================================  ==========
device          reader pulp, FSR unit, motor, drive train from               population
                :func:`~ebraille_sim.scenarios.population.sample_device`
reading         passage (shipped passages), excerpt start (a word start in   [R] paper
                its text), rate uniform in ``wpm_range``
setpoint        1 to ``max_setpoint_levels`` levels uniform in               [E]
                ``setpoint_range_n``; steps at uniform times during reading
finger          gap uniform in ``gap_range_m``; ``[disturbances.tremor]``    [R]/[E]
                RMS uniform in ``tremor_rms_range_m`` (band
                ``tremor_band_hz``); ``[disturbances.pressing]`` (slow
                drift) RMS uniform in ``drift_rms_range_m`` (band
                ``drift_band_hz``)
supply          with probability ``battery_probability`` one Li-ion cell     [E]
                (``[disturbances.battery]``, state of charge uniform in
                ``battery_soc_range``), otherwise the device's supply sagged
                by a fraction uniform in ``supply_sag_range``
                (``[device] driver_supply_v``)
==============  ===========================================================  ==========

Examples
--------
>>> import numpy as np
>>> dist = EpisodeDistribution()
>>> spec = dist.draw(np.random.SeedSequence(3))
>>> spec.reading.max_characters, sorted(spec.sections["disturbances"])[:2]
(30, ['pressing', 'tremor'])
>>> EpisodeDistribution(wpm_range=(120.0, 60.0))
Traceback (most recent call last):
...
ValueError: wpm_range must have low <= high, got (120.0, 60.0)
"""
from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, field

import numpy as np

from ebraille_sim.base.validation import replace_fields
from ebraille_sim.physics.params import TACTILE_FORCE_MAX_N, DeviceParams
from ebraille_sim.scenarios.draws import episode_numbers
from ebraille_sim.scenarios.population import PopulationSpec
from ebraille_sim.scenarios.spec import ControllerSpec, FingerSpec, ReadingSpec, ScenarioSpec, SetpointSpec

__all__ = ["EPISODE_SOURCE", "FIXED_KEYS", "MAX_DEVICE_POOL", "EpisodeDistribution", "passage_word_starts"]

EPISODE_SOURCE = "episode"
"""``source`` of a drawn spec (the prefix of its error messages)."""

FIXED_KEYS = ("device", "passage", "first_character", "wpm", "setpoint_n", "setpoint_steps", "gap_m",
              "drift_amplitude_m", "tremor_amplitude_m", "supply_fraction", "disturbances")
"""Components :meth:`EpisodeDistribution.draw` can be told to fix (the env's reset options)."""


def _number(name, value, lo, hi, lo_open=False, hi_open=False):
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"{name} must be a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value) or value < lo or value > hi or (lo_open and value == lo) or (hi_open and value == hi):
        lb, rb = "(" if lo_open else "[", ")" if hi_open else "]"
        raise ValueError(f"{name} = {value!r} is out of range {lb}{lo:g}, {hi:g}{rb}")
    return value


def _pair(name, value, lo, hi, strict=False):
    if not isinstance(value, (tuple, list)) or len(value) != 2:
        raise ValueError(f"{name} must be a (low, high) pair, got {value!r}")
    a, b = _number(f"{name}[0]", value[0], lo, hi), _number(f"{name}[1]", value[1], lo, hi)
    if a > b or (strict and a == b):
        raise ValueError(f"{name} must have low {'<' if strict else '<='} high, got {tuple(value)!r}")
    return (a, b)


@functools.lru_cache(maxsize=16)
def _passage(name: str) -> tuple[str, tuple[int, ...]]:
    from ebraille_sim.scenarios.passages import load_passage
    text = load_passage(name)
    return text, tuple(passage_word_starts(text))


def passage_word_starts(text: str) -> list[int]:
    """Character offsets of the word starts of ``text`` (0 and every non-space after a space)."""
    return [0] + [i + 1 for i in range(len(text) - 1) if text[i].isspace() and not text[i + 1].isspace()]


def _excerpt(text: str, start: int, n_cells: int) -> str:
    """Text from ``start`` (wrapping to the passage's beginning) that transcribes to at
    least ``n_cells`` cells, cut at a word end.  Every character gives at least one cell, so
    ``n_cells`` characters suffice."""
    sep = "" if text[-1].isspace() else "\n"
    src = text[start:]
    while len(src) <= n_cells:
        src += sep + text
    end = n_cells
    while end < len(src) and not src[end].isspace():
        end += 1
    return src[:end]


(_U_PASSAGE, _U_START, _U_WPM, _U_LEVELS, _U_GAP, _U_TREMOR, _U_DRIFT, _U_BATTERY, _U_SOC, _U_SAG) = range(10)
_N_EPISODE_UNIFORMS = 10
"""Slots of an episode's uniform variates (module docstring); the setpoint's levels and step
times follow them (``max_setpoint_levels`` and one fewer)."""


def _index(u: float, n: int) -> int:
    """The index in ``range(n)`` of the uniform variate ``u`` on [0, 1)."""
    return min(int(u * n), n - 1)


_DRAWN_KEYS = {"tremor": "rms_m", "pressing": "rms_m", "battery": "soc_start"}
"""The key of each drawn ``[disturbances]`` sub-table that changes from episode to episode."""


def _validated_section(table: dict) -> dict:
    """``validate_section(EPISODE_SOURCE, table)`` of a drawn table, cheaply: each sub-table's
    constant keys (band, cells) are validated once (:func:`_validated_kind`) and its drawn value
    (:data:`_DRAWN_KEYS`), a float inside its range, replaces the default of that object; a
    table with any other value, or any other key, goes through ``validate_section`` whole, so
    its errors are the same."""
    from ebraille_sim.scenarios.disturbances import KINDS, validate_section
    out = {}
    for name, sub in table.items():
        key = _DRAWN_KEYS.get(name)
        value = sub.get(key) if key is not None else None
        meta = KINDS[name].__dataclass_fields__[key].metadata if key is not None else None
        if type(value) is not float or not meta["lo"] <= value <= meta["hi"]:
            return validate_section(EPISODE_SOURCE, table)
        fixed = tuple((k, tuple(v) if isinstance(v, list) else v) for k, v in sub.items() if k != key)
        out[name] = replace_fields(_validated_kind(name, fixed), **{key: value})
    return out


@functools.lru_cache(maxsize=64)
def _validated_kind(name: str, fixed: tuple):
    """The validated parameter object of ``[disturbances.<name>]`` with the keys ``fixed``
    (``(key, value)`` pairs, lists as tuples) and its defaults otherwise: the part of a drawn
    sub-table that stays the same over a distribution's episodes (a frozen object, shared)."""
    from ebraille_sim.scenarios.disturbances import validate_section
    return validate_section(EPISODE_SOURCE, {name: {k: list(v) if isinstance(v, tuple) else v
                                                    for k, v in fixed}})[name]


MAX_DEVICE_POOL = 10000
"""Most units of :attr:`EpisodeDistribution.device_pool` (a drawn device and what its bench
measured take about 3.3 kB, so a full pool about 33 MB; the pool holds every unit it has drawn)."""


@dataclass(frozen=True)
class EpisodeDistribution:
    """Ranges of the episodes an environment trains on (module docstring: the draws).

    Attributes
    ----------
    base_device : DeviceParams
        Centre of the population; its rates are the episodes' rates.
    population : PopulationSpec or None
        Device population; None runs every episode on ``base_device``.
    passages : tuple of str or None
        Passage names to draw from; None: every shipped passage.
    episode_characters : int
        Braille cells read per episode (the episode ends when the last one leaves).
    reading_start_s : float
        Contact onset time before the first cell, s.
    wpm_range : (float, float)
        Reading rate, words per minute.
    setpoint_range_n : (float, float)
        Setpoint levels, N (at most the tactile maximum).
    max_setpoint_levels : int
        Levels per episode are uniform in 1 .. this.
    step_end_margin_s : float
        Setpoint steps fall between the reading start and this long before its end, s.
    gap_range_m : (float, float)
        Pulp surface above the retracted board, m.
    tremor_rms_range_m, tremor_band_hz : (float, float)
        ``[disturbances.tremor]`` RMS (m) and band (Hz).
    drift_rms_range_m, drift_band_hz : (float, float)
        ``[disturbances.pressing]`` RMS (m) and band (Hz): the slow drift of the pulp.
    supply_sag_range : (float, float)
        Fraction by which the device's driver supply sags (no battery).
    battery_probability : float
        Chance that an episode runs from one Li-ion cell instead.
    battery_soc_range : (float, float)
        State of charge of that cell at the start.
    disturbances : bool
        False: no tremor, drift, sag or battery.
    device_pool : int
        0 (the default): every episode draws a new device from ``population``.  N > 0: the
        episodes share a pool of N devices, unit ``k`` being
        ``sample_devices(device_pool_seed, N)[k]`` of the population (reader, FSR unit, motor,
        drive train and board, calibrated on its bench once, when first drawn, and kept for
        the distribution's life); each episode takes unit ``k`` from its own device stream,
        uniform over the pool.  A reset that reuses a unit skips its bench and the caches keyed
        on its parts hit (:data:`MAX_DEVICE_POOL` units at most).
    device_pool_seed : int
        Seed of the pool's units (the pool is the same for every env seed).
    """
    base_device: DeviceParams = field(default_factory=DeviceParams)
    population: PopulationSpec | None = field(default_factory=PopulationSpec)
    passages: tuple | None = None
    episode_characters: int = 30
    reading_start_s: float = 1.0
    wpm_range: tuple = (60.0, 120.0)
    setpoint_range_n: tuple = (0.3, 1.5)
    max_setpoint_levels: int = 3
    step_end_margin_s: float = 0.5
    gap_range_m: tuple = (0.5e-3, 1.5e-3)
    tremor_rms_range_m: tuple = (0.0, 20e-6)
    tremor_band_hz: tuple = (8.0, 12.0)
    drift_rms_range_m: tuple = (0.0, 0.1e-3)
    drift_band_hz: tuple = (0.1, 1.0)
    supply_sag_range: tuple = (0.0, 0.15)
    battery_probability: float = 0.25
    battery_soc_range: tuple = (0.05, 1.0)
    disturbances: bool = True
    device_pool: int = 0
    device_pool_seed: int = 0

    def __post_init__(self):
        from ebraille_sim.scenarios.passages import list_passages
        if not isinstance(self.base_device, DeviceParams):
            raise ValueError(f"base_device must be a DeviceParams, got {type(self.base_device).__name__}")
        if self.population is not None and not isinstance(self.population, PopulationSpec):
            raise ValueError(f"population must be a PopulationSpec or None, got {type(self.population).__name__}")
        names = list_passages()
        if self.passages is not None:
            if isinstance(self.passages, str) or not isinstance(self.passages, (tuple, list)) or not self.passages:
                raise ValueError(f"passages must be a non-empty tuple of passage names or None, got {self.passages!r}")
            for p in self.passages:
                if p not in names:
                    raise ValueError(f"passage {p!r} is not one of: {', '.join(names)}")
            object.__setattr__(self, "passages", tuple(self.passages))
        for name, hi in (("episode_characters", 100000), ("max_setpoint_levels", 100)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not 1 <= v <= hi:
                raise ValueError(f"{name} must be an integer in [1, {hi}], got {v!r}")
        _number("reading_start_s", self.reading_start_s, 0.0, 600.0)
        _number("step_end_margin_s", self.step_end_margin_s, 0.0, 600.0)
        nyquist = 0.5 * self.base_device.rates.control_rate_hz
        pairs = {"wpm_range": (1.0, 1000.0, False), "setpoint_range_n": (0.01, TACTILE_FORCE_MAX_N, False),
                 "gap_range_m": (0.0, 5e-3, False), "tremor_rms_range_m": (0.0, 1e-4, False),
                 "tremor_band_hz": (0.0, 100.0, True), "drift_rms_range_m": (0.0, 1e-3, False),
                 "drift_band_hz": (0.0, 20.0, True), "supply_sag_range": (0.0, 0.5, False),
                 "battery_soc_range": (0.05, 1.0, False)}
        for name, (lo, hi, strict) in pairs.items():
            object.__setattr__(self, name, _pair(name, getattr(self, name), lo, hi, strict))
        for name in ("tremor_band_hz", "drift_band_hz"):
            if getattr(self, name)[1] >= nyquist:
                raise ValueError(f"{name} upper edge {getattr(self, name)[1]:g} Hz must be below the Nyquist "
                                 f"frequency {nyquist:g} Hz of the {2 * nyquist:g} Hz control rate")
        _number("battery_probability", self.battery_probability, 0.0, 1.0)
        if not isinstance(self.disturbances, bool):
            raise ValueError(f"disturbances must be True or False, got {self.disturbances!r}")
        for name, hi in (("device_pool", MAX_DEVICE_POOL), ("device_pool_seed", 2 ** 63 - 1)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not 0 <= v <= hi:
                raise ValueError(f"{name} must be an integer in [0, {hi}], got {v!r}")
            object.__setattr__(self, name, int(v))
        if self.device_pool and self.population is None:
            raise ValueError("device_pool draws its units from the population: it needs a population "
                             "(randomize_device=True)")
        object.__setattr__(self, "_pool", {})          # unit k of the pool, once drawn (not a field)

    # -------------------------------------------------------------------------------------
    def pool_device(self, k: int) -> DeviceParams:
        """Unit ``k`` of the device pool (``device_pool`` > 0): device ``k`` of
        :func:`ebraille_sim.scenarios.population.sample_devices` of ``device_pool_seed`` under the
        population, drawn and calibrated the first time it is asked for and kept."""
        if not 0 <= k < self.device_pool:
            raise ValueError(f"pool unit {k!r} is out of range [0, {self.device_pool - 1}] "
                             f"(device_pool = {self.device_pool})")
        dev = self._pool.get(k)
        if dev is None:
            from ebraille_sim.base.seeds import SeedNode
            from ebraille_sim.scenarios.population import sample_device
            dev = sample_device(SeedNode(self.device_pool_seed, spawn_key=(k,)), self.population, self.base_device)
            self._pool[k] = dev
        return dev

    def max_duration_s(self) -> float:
        """Longest episode: the onset and every cell at the slowest rate, s."""
        from ebraille_sim.scenarios.reading import mean_dwell_s
        return self.reading_start_s + self.episode_characters * mean_dwell_s(self.wpm_range[0])

    def draw(self, seed_sequence: np.random.SeedSequence, fixed: dict | None = None) -> ScenarioSpec:
        """Draw one episode's scenario specification.

        Parameters
        ----------
        seed_sequence : numpy.random.SeedSequence
            The episode's seed (module docstring: what each of its children draws).
        fixed : dict, optional
            Components to fix instead of drawing, keys :data:`FIXED_KEYS` (validated by
            the caller, :func:`ebraille_sim.rl.episode.validate_options`): ``device`` (its
            rates are replaced by the episodes'), ``passage``, ``first_character``
            (character offset of the excerpt in the passage text), ``wpm``,
            ``setpoint_n`` and ``setpoint_steps`` (``(time_s, force_n)`` pairs),
            ``gap_m``, ``drift_amplitude_m`` and ``tremor_amplitude_m`` (the RMS is the
            amplitude over sqrt 2, as for a sine), ``supply_fraction`` (driver supply as a
            fraction of the device's, no battery), ``disturbances`` (False: none).

        Returns
        -------
        ScenarioSpec
            Source ``"episode"``, ``duration_s`` None (the run ends with the excerpt).
        """
        from ebraille_sim.scenarios.passages import list_passages
        from ebraille_sim.scenarios.population import device_from_variates
        from ebraille_sim.scenarios.reading import mean_dwell_s

        opt = fixed or {}
        unknown = set(opt) - set(FIXED_KEYS)
        if unknown:
            raise ValueError(f"unknown fixed component {sorted(unknown)[0]!r}; allowed: {', '.join(FIXED_KEYS)}")
        # every number of the episode in one compiled call: the device's streams, then the run
        # seed and a fixed number of uniforms in a fixed order (module docstring)
        levels_max = self.max_setpoint_levels
        u_dev, z_dev, run_seed, u = episode_numbers(seed_sequence, _N_EPISODE_UNIFORMS + 2 * levels_max - 1)
        base = self.base_device
        if "device" in opt:
            dev = dataclasses.replace(opt["device"], rates=base.rates)
        elif self.device_pool:
            dev = self.pool_device(_index(u_dev[0], self.device_pool))
        elif self.population is not None:
            dev = device_from_variates(u_dev, z_dev, self.population, base)
        else:
            dev = base

        # reading: passage, excerpt start at a word start of its text, rate
        names = self.passages or tuple(list_passages())
        passage = opt.get("passage", names[_index(u[_U_PASSAGE], len(names))])
        text, starts = _passage(passage)
        first = opt.get("first_character", starts[_index(u[_U_START], len(starts))])
        if first >= len(text):
            raise ValueError(f"option 'first_character' = {first} is out of range [0, {len(text) - 1}] "
                             f"for passage {passage!r}")
        lo, hi = self.wpm_range
        wpm = float(opt.get("wpm", lo + (hi - lo) * u[_U_WPM]))
        n_cells = self.episode_characters
        reading = ReadingSpec(passage=passage, text=_excerpt(text, first, n_cells), wpm=wpm,
                              start_s=float(self.reading_start_s), max_characters=n_cells)
        t_end_s = self.reading_start_s + n_cells * mean_dwell_s(wpm)

        # setpoint: levels and step times
        n_levels = 1 + _index(u[_U_LEVELS], levels_max)
        lo, hi = self.setpoint_range_n
        levels = [lo + (hi - lo) * x for x in u[_N_EPISODE_UNIFORMS:_N_EPISODE_UNIFORMS + n_levels]]
        t_lo = self.reading_start_s
        t_hi = max(t_lo, t_end_s - self.step_end_margin_s)
        times = sorted(t_lo + (t_hi - t_lo) * x for x in u[_N_EPISODE_UNIFORMS + levels_max:
                                                            _N_EPISODE_UNIFORMS + levels_max + n_levels - 1])
        if "setpoint_n" in opt or "setpoint_steps" in opt:
            steps = tuple((float(t), float(f)) for t, f in opt.get("setpoint_steps", ()))
            setpoint = SetpointSpec(force_n=float(opt.get("setpoint_n", levels[0])), steps=steps)
        else:
            setpoint = SetpointSpec(force_n=levels[0], steps=tuple(zip(times, levels[1:])))

        # finger: gap, tremor and slow drift; supply: a sagging regulated supply or one Li-ion cell
        gap, tremor_rms, drift_rms, soc, sag = (
            lo + (hi - lo) * u[i] for i, (lo, hi) in
            ((_U_GAP, self.gap_range_m), (_U_TREMOR, self.tremor_rms_range_m), (_U_DRIFT, self.drift_rms_range_m),
             (_U_SOC, self.battery_soc_range), (_U_SAG, self.supply_sag_range)))
        on_battery = u[_U_BATTERY] < self.battery_probability
        disturb = self.disturbances and opt.get("disturbances", True)
        if not disturb:
            tremor_rms = drift_rms = sag = 0.0
            on_battery = False
        gap = float(opt.get("gap_m", gap))
        if "tremor_amplitude_m" in opt:
            tremor_rms = opt["tremor_amplitude_m"] / math.sqrt(2.0)
        if "drift_amplitude_m" in opt:
            drift_rms = opt["drift_amplitude_m"] / math.sqrt(2.0)
        supply_fraction = 1.0 if on_battery else 1.0 - sag
        if "supply_fraction" in opt:
            supply_fraction, on_battery = float(opt["supply_fraction"]), False
        if supply_fraction != 1.0:
            dev = replace_fields(dev, driver_supply_v=dev.driver_supply_v * supply_fraction)

        table = {}
        if tremor_rms > 0:
            table["tremor"] = {"rms_m": tremor_rms, "band_hz": list(self.tremor_band_hz)}
        if drift_rms > 0:
            table["pressing"] = {"rms_m": drift_rms, "band_hz": list(self.drift_band_hz)}
        if on_battery:
            table["battery"] = {"cells_series": 1, "soc_start": soc}
        sections = {"disturbances": _validated_section(table)} if table else {}
        return ScenarioSpec(
            name="episode", seed=run_seed,
            description=f"passage {passage!r} from character {first}, {wpm:.1f} wpm",
            duration_s=None, reading=reading, setpoint=setpoint, device=dev, finger=FingerSpec(gap_m=gap),
            controller=ControllerSpec(), criteria={}, sections=sections, source=EPISODE_SOURCE)
