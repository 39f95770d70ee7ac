"""Episodes of the Gymnasium env: its configuration, the draw of one episode and its inputs.

:class:`EnvConfig` holds the env's validated arguments and the
:class:`~ebraille_sim.scenarios.episodes.EpisodeDistribution` they define;
:func:`draw_episode` draws one scenario specification from an episode seed and builds its
inputs with :func:`ebraille_sim.scenarios.inputs.build_run_inputs`, the scenario runner's
function (:func:`episode_from_spec`), so ``run_scenario(episode.spec)`` replays the episode;
:func:`validate_options` checks the reset options that fix components of the draw
(:data:`OPTION_KEYS`).  The env itself and its compiled step are in :mod:`ebraille_sim.rl.env`,
which re-exports every name of this module.

Examples
--------
>>> import numpy as np
>>> cfg = EnvConfig(randomize_device=False)
>>> ep = draw_episode(np.random.SeedSequence(3), cfg, validate_options({"wpm": 90.0}, cfg.safe_force_n))
>>> ep.wpm, ep.setpoint_n.shape == (ep.n_steps + 1,)
(90.0, True)
"""
from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass

import numpy as np

from controllers import features
from ebraille_sim.base.validation import check_bool, check_choice, check_number, check_pair, check_range
from ebraille_sim.physics.params import TACTILE_FORCE_MAX_N
from ebraille_sim.plant.layout import U

__all__ = ["MAX_EPISODE_STEPS", "OPTION_KEYS", "EnvConfig", "Episode", "draw_episode", "episode_from_spec",
           "estimator_model", "validate_options"]

OPTION_KEYS = ("device", "passage", "first_character", "wpm", "setpoint_n", "setpoint_steps", "gap_m",
               "drift_amplitude_m", "tremor_amplitude_m", "supply_fraction", "disturbances")

@dataclass(frozen=True)
class EnvConfig:
    """Constructor arguments of :class:`ContactForceEnv`, validated (see its table), and the
    time constants of the observation's rate filter and error integral."""
    control_rate_hz: float = 200.0
    safe_force_n: float = TACTILE_FORCE_MAX_N
    warn_force_n: float = 2.0
    episode_characters: int = 30
    reading_start_s: float = 1.0
    wpm_range: tuple = (60.0, 120.0)
    setpoint_range_n: tuple = (0.3, 1.5)
    randomize_device: bool = True
    disturbances: bool = True
    effort_weight: float = 0.1
    violation_weight: float = 1.0
    rate_filter_s: float = 0.02
    integral_time_s: float = 0.1
    backend: str = "lumped"
    base_device: object = None
    safety: bool = True
    device_pool: int = 0
    device_pool_seed: int = 0

    def __post_init__(self):
        from ebraille_sim.physics.params import DeviceParams, RateParams
        check_range("control_rate_hz", self.control_rate_hz, 1.0, 1e5)
        check_range("safe_force_n", self.safe_force_n, 0.0, 20.0, lo_open=True)
        check_range("warn_force_n", self.warn_force_n, 0.0, self.safe_force_n, hi_open=True)
        object.__setattr__(self, "episode_characters",
                           check_number("episode_characters", self.episode_characters, 1, 100000, integer=True))
        check_range("reading_start_s", self.reading_start_s, 0.0, 60.0)
        object.__setattr__(self, "wpm_range", check_pair("wpm_range", self.wpm_range, 1.0, 1000.0))
        object.__setattr__(self, "setpoint_range_n",
                           check_pair("setpoint_range_n", self.setpoint_range_n, 0.01, self.warn_force_n))
        check_bool("randomize_device", self.randomize_device)
        check_bool("disturbances", self.disturbances)
        check_bool("safety", self.safety)
        from ebraille_sim.scenarios.episodes import MAX_DEVICE_POOL
        object.__setattr__(self, "device_pool",
                           check_number("device_pool", self.device_pool, 0, MAX_DEVICE_POOL, integer=True))
        object.__setattr__(self, "device_pool_seed",
                           check_number("device_pool_seed", self.device_pool_seed, 0, 2 ** 63 - 1, integer=True))
        if self.device_pool and not self.randomize_device:
            raise ValueError("device_pool draws its units from the device population: it needs randomize_device=True")
        check_range("effort_weight", self.effort_weight, 0.0, 100.0)
        check_range("violation_weight", self.violation_weight, 0.0, 100.0)
        check_range("rate_filter_s", self.rate_filter_s, 0.0, 10.0)
        check_range("integral_time_s", self.integral_time_s, 0.0, 100.0, lo_open=True)
        if not isinstance(self.backend, str):
            raise ValueError(f"backend must be a string, got {self.backend!r}")
        base = DeviceParams() if self.base_device is None else self.base_device
        if not isinstance(base, DeviceParams):
            raise ValueError(f"base_device must be a DeviceParams, got {type(base).__name__}")
        r = base.rates
        try:
            rates = RateParams(control_rate_hz=float(self.control_rate_hz), sensor_rate_hz=r.sensor_rate_hz,
                               physics_rate_hz=r.physics_rate_hz)
        except ValueError as exc:
            raise ValueError(f"control_rate_hz {self.control_rate_hz:g}: {exc}") from None
        object.__setattr__(self, "base_device", dataclasses.replace(base, rates=rates))
        object.__setattr__(self, "control_rate_hz", float(self.control_rate_hz))
        # validates the episode ranges at this rate; kept on the instance (not a field), so a
        # reset does not hash the config to find it
        object.__setattr__(self, "_distribution", _distribution(self))

    def distribution(self):
        """The :class:`~ebraille_sim.scenarios.episodes.EpisodeDistribution` of this config's
        episodes (built once per config)."""
        return self._distribution
    @property
    def dt_s(self) -> float:
        return 1.0 / self.control_rate_hz

    @property
    def substeps(self) -> int:
        return self.base_device.rates.substeps_per_control

    @property
    def current_scale_a(self) -> float:
        """Current scale of the observation: the base device's stall current at its driver
        supply, ``driver_supply_v / resistance_ohm``, A ([D] 6 V / 21.2 ohm = 0.283 A)."""
        return self.base_device.driver_supply_v / self.base_device.motor.resistance_ohm

    def config_vector(self, driver_supply_v: float | None = None) -> np.ndarray:
        """The per-env configuration vector ``c`` of :func:`observe` and :func:`reward_of`.

        ``driver_supply_v`` (default: the base device's) turns an action into volts.
        """
        supply = self.base_device.driver_supply_v if driver_supply_v is None else driver_supply_v
        return features.config_vector(self.control_rate_hz, self.safe_force_n, self.warn_force_n,
                                      self.rate_filter_s, self.integral_time_s, supply,
                                      self.effort_weight, self.violation_weight, self.current_scale_a)

    def max_episode_steps(self) -> int:
        """Steps of the longest episode at this config's control rate: the onset and every
        cell at the slowest rate of ``wpm_range``."""
        return int(math.ceil(self.distribution().max_duration_s() * self.control_rate_hz - 1e-9))

    def policy_metadata(self) -> dict:
        """What a policy controller needs to rebuild the observation (JSON-serialisable).

        Always records ``current_scale_a`` (:attr:`current_scale_a`); a reader of a file
        written without it assumes :data:`controllers.features.CURRENT_SCALE_A` (the nominal
        drive's 6 V / 21.2 ohm).
        """
        return {"control_rate_hz": self.control_rate_hz, "safe_force_n": self.safe_force_n,
                "warn_force_n": self.warn_force_n, "rate_filter_s": self.rate_filter_s,
                "integral_time_s": self.integral_time_s, "effort_weight": self.effort_weight,
                "violation_weight": self.violation_weight,
                "driver_supply_v": self.base_device.driver_supply_v, "current_scale_a": self.current_scale_a}

    def estimator_metadata(self) -> dict:
        """Every :class:`~ebraille_sim.physics.params.EstimatorParams` field of the base device,
        which every drawn device keeps: the firmware a policy trained on this config met
        (JSON-serialisable; recorded in ``policy.json``'s ``training``)."""
        return dataclasses.asdict(self.base_device.estimator)


@functools.lru_cache(maxsize=32)
def _distribution(cfg: EnvConfig):
    from ebraille_sim.scenarios.episodes import EpisodeDistribution
    from ebraille_sim.scenarios.population import PopulationSpec
    try:
        return EpisodeDistribution(
            base_device=cfg.base_device, population=PopulationSpec() if cfg.randomize_device else None,
            episode_characters=cfg.episode_characters, reading_start_s=cfg.reading_start_s,
            wpm_range=cfg.wpm_range, setpoint_range_n=cfg.setpoint_range_n, disturbances=cfg.disturbances,
            device_pool=cfg.device_pool, device_pool_seed=cfg.device_pool_seed)
    except ValueError as exc:
        raise ValueError(f"control_rate_hz {cfg.control_rate_hz:g}: {exc}") from None


MAX_EPISODE_STEPS = EnvConfig().max_episode_steps()
"""The longest episode at the defaults (1 s of onset + 30 cells at 60 wpm, 0.2 s each, at
200 Hz: 1400 steps).  Other configs: :meth:`EnvConfig.max_episode_steps` (7000 steps at
1 kHz).  The env truncates itself when its excerpt ends, so the registered id carries no
fixed ``TimeLimit`` that would be wrong at another control rate."""


@dataclass(frozen=True, eq=False)
class Episode:
    """One episode: its drawn scenario spec and the run inputs built from it.

    Attributes
    ----------
    spec : ScenarioSpec
        Drawn by :meth:`ebraille_sim.scenarios.episodes.EpisodeDistribution.draw`; running
        it with :func:`ebraille_sim.scenarios.runner.run_scenario` gives the same episode.
    run : RunInputs
        :func:`ebraille_sim.scenarios.inputs.build_run_inputs` of ``spec``.
    device : DeviceParams
        ``spec.device`` (rates set to the env's; a sagged supply in ``driver_supply_v``).
    sensor_seed : float
        Seed of the ADC noise (52-bit integer as float).
    schedule : ReadingSchedule
    passage : str
        The passage the excerpt comes from (its start: ``spec.description``).
    wpm : float
    n_steps : int
        Steps until the excerpt ends (truncation).
    setpoint_n : ndarray, shape (n_steps + 1,)
        Setpoint at ``t_k = k dt``.
    finger_m : ndarray, shape (n_steps,)
        Pulp surface position held over step k (gap, tremor, drift).
    supply_v : float
        Driver supply during the first step, V (a battery's supply varies over the episode).
    gap_m : float
    char_index : ndarray of int, shape (n_steps + 1,)
        Cell on the display at ``t_k`` (-1 before the first and after the last).
    """
    spec: object
    run: object
    device: object
    sensor_seed: float
    schedule: object
    passage: str
    wpm: float
    n_steps: int
    setpoint_n: np.ndarray
    finger_m: np.ndarray
    supply_v: float
    gap_m: float
    char_index: np.ndarray


def estimator_model(spec: str):
    """The estimator model named ``spec``, loaded once per process (the registry's cache,
    :func:`ebraille_sim.estimation.registry.cached_model`, shared with the scenario runner)."""
    from ebraille_sim.estimation.registry import cached_model
    return cached_model(spec)


def validate_options(options, safe_force_n: float) -> dict:
    """Check reset options; return a plain dict.  Unknown keys and bad values raise ``ValueError``."""
    if options is None:
        return {}
    if not isinstance(options, dict):
        raise ValueError(f"options must be a dict, got {type(options).__name__}")
    out = {}
    for key, value in options.items():
        if key not in OPTION_KEYS:
            raise ValueError(f"unknown reset option {key!r}; allowed: {', '.join(OPTION_KEYS)}")
        if key == "device":
            from ebraille_sim.physics.params import DeviceParams
            if not isinstance(value, DeviceParams):
                raise ValueError(f"option 'device' must be a DeviceParams, got {type(value).__name__}")
        elif key == "passage":
            from ebraille_sim.scenarios.passages import list_passages
            check_choice("option 'passage'", value, list_passages())
        elif key == "first_character":
            value = check_number("option 'first_character'", value, lo=0, integer=True)
        elif key == "wpm":
            value = check_range("option 'wpm'", value, 1.0, 1000.0)
        elif key == "setpoint_n":
            value = check_range("option 'setpoint_n'", value, 0.0, safe_force_n, lo_open=True, hi_open=True)
        elif key == "setpoint_steps":
            if not isinstance(value, (list, tuple)) or not all(
                    isinstance(s, (list, tuple)) and len(s) == 2 for s in value):
                raise ValueError("option 'setpoint_steps' must be a list of (time_s, force_n) pairs")
            steps = [(check_range("option 'setpoint_steps' time", t, 0.0, 3600.0),
                      check_range("option 'setpoint_steps' force", f, 0.0, safe_force_n, lo_open=True,
                                  hi_open=True)) for t, f in value]
            if any(b[0] <= a[0] for a, b in zip(steps, steps[1:])):
                raise ValueError("option 'setpoint_steps' times must increase")
            value = tuple(steps)
        elif key == "gap_m":
            value = check_range("option 'gap_m'", value, 0.0, 5e-3)
        elif key == "drift_amplitude_m":
            value = check_range("option 'drift_amplitude_m'", value, 0.0, 1e-3)
        elif key == "tremor_amplitude_m":
            value = check_range("option 'tremor_amplitude_m'", value, 0.0, 1e-4)
        elif key == "supply_fraction":
            value = check_range("option 'supply_fraction'", value, 0.5, 1.0)
        elif key == "disturbances":
            check_bool("option 'disturbances'", value)
        out[key] = value
    return out


def episode_from_spec(spec) -> Episode:
    """The episode of a scenario spec: its run inputs (:func:`ebraille_sim.scenarios.inputs.build_run_inputs`,
    the runner's function) and the arrays the env steps through."""
    from ebraille_sim.scenarios.inputs import build_run_inputs
    run = build_run_inputs(spec)
    n = run.n_steps
    finger = run.profiles.get("finger_pos_m")
    if finger is None:
        finger = np.full(n, run.base_inputs[U.finger_pos_m])
    return Episode(spec=spec, run=run, device=spec.device, sensor_seed=run.sensor_seed, schedule=run.schedule,
                   passage=spec.reading.passage, wpm=float(spec.reading.wpm),
                   n_steps=n, setpoint_n=run.setpoint_n, finger_m=finger,
                   supply_v=run.input_at("driver_supply_v", 0), gap_m=float(spec.finger.gap_m),
                   char_index=run.schedule.index_at(run.t_s))


def draw_episode(ss, cfg: EnvConfig, options: dict | None = None) -> Episode:
    """Draw one episode from the episode seed ``ss`` (a NumPy ``SeedSequence`` or a
    :class:`~ebraille_sim.base.seeds.SeedNode`): a spec from the config's
    :meth:`~EnvConfig.distribution` (``options``, validated by :func:`validate_options`,
    fix components), then its inputs (:func:`episode_from_spec`)."""
    return episode_from_spec(cfg.distribution().draw(ss, options))
