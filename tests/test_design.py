"""Controller designs on the sampled plant (ebraille_sim.analysis.design)."""
import dataclasses

from ebraille_sim.analysis.design import simc_pid
from ebraille_sim.analysis.margins import analyse_loop


def test_simc_gains_are_robust_on_the_nominal_plant():
    cfg = simc_pid(force_n=1.0)
    assert cfg.kp_v_per_n > 0 and cfg.ki_v_per_ns > 0
    a = analyse_loop(dataclasses.replace(cfg, kp_v_per_n=0.5 * cfg.kp_v_per_n, ki_v_per_ns=0.5 * cfg.ki_v_per_ns),
                     force_n=1.0)
    assert a.stable and a.step["SettlingTime"] < 2.0
