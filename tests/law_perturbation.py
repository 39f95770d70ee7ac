"""Does every law have a test that catches a 5 % change of it?

For each law this script copies the package (and its tests) to a temporary directory,
multiplies every value the law's function returns by 1.05 in the copied source, runs
``pytest`` on the law tests against the copy, and prints a Markdown table: the law, its
``file:function``, how many tests failed, and which of the law's own tests failed.  A law
whose own tests all pass under the change is reported as not caught, and the script exits
with status 1.

Numba recompiles the whole kernel for every copy (each copy gets its own
``NUMBA_CACHE_DIR``), so a run takes a few minutes per law.

Run:  python tests/law_perturbation.py [--law NAME ...] [--tests FILE ...] [--keep]
"""
from __future__ import annotations

import argparse
import ast
import os
import pathlib
import re
import shutil
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent
COPY = ("ebraille_sim", "controllers", "tests", "scenarios", "pyproject.toml")
DEFAULT_TESTS = ("tests/test_laws.py", "tests/test_plant_physics.py", "tests/test_sensor_chain.py",
                 "tests/test_supervisor.py")
FACTOR = "1.05"

LAWS = [
    # (law, file, function, own tests in tests/test_laws.py)
    ("motor current step", "ebraille_sim/physics/motor.py", "current_step",
     ["test_motor_current_step_follows_the_closed_form_exponential"]),
    ("armature ODE", "ebraille_sim/physics/motor.py", "current_rate_a_per_s",
     ["test_armature_ode_is_the_rate_of_the_exact_current_step"]),
    ("gear loss", "ebraille_sim/physics/drivetrain.py", "gear_loss_n",
     ["test_gear_loss_reproduces_the_forward_efficiency"]),
    ("mesh force", "ebraille_sim/physics/drivetrain.py", "mesh_force",
     ["test_mesh_force_in_and_out_of_the_backlash_gap"]),
    ("Stribeck friction", "ebraille_sim/physics/drivetrain.py", "stribeck",
     ["test_stribeck_curve_at_rest_at_vs_and_far_above"]),
    ("pulp elastic force", "ebraille_sim/physics/fingertip.py", "elastic_force",
     ["test_pulp_elastic_force_at_the_paper_derived_compressions"]),
    ("QLV relaxation", "ebraille_sim/physics/fingertip.py", "prony_step",
     ["test_qlv_step_response_relaxes_to_c0_fe_with_the_three_time_constants",
      "test_qlv_ramp_is_exact_and_contact_only_pushes"]),
    ("pulp ramp compression", "ebraille_sim/physics/fingertip.py", "ramp_compression_at_force_m",
     ["test_ramp_compression_follows_the_qlv_law_between_its_relaxed_and_instant_limits"]),
    ("pulp dynamic stiffness", "ebraille_sim/physics/fingertip.py", "dynamic_stiffness_n_per_m",
     ["test_dynamic_stiffness_is_the_tangent_stiffness_times_the_relaxation_modulus"]),
    ("pulp relaxation modulus", "ebraille_sim/physics/fingertip.py", "complex_relaxation",
     ["test_dynamic_stiffness_is_the_tangent_stiffness_times_the_relaxation_modulus"]),
    ("Prony ODE", "ebraille_sim/physics/fingertip.py", "prony_rate_n_per_s",
     ["test_prony_ode_is_the_rate_of_the_exact_prony_step"]),
    ("FSR conductance", "ebraille_sim/physics/fsr.py", "conductance_s", ["test_fsr_conductance_power_law"]),
    ("FSR turn-on", "ebraille_sim/physics/fsr.py", "turn_on_factor",
     ["test_fsr_turn_on_region_has_the_datasheet_actuation"]),
    ("FSR temperature", "ebraille_sim/physics/fsr.py", "temperature_factor",
     ["test_fsr_temperature_law_has_the_datasheet_points"]),
    ("FSR press scatter", "ebraille_sim/physics/fsr.py", "press_scatter",
     ["test_press_scatter_draws_once_per_press_with_the_datasheet_repeatability"]),
    ("creep force", "ebraille_sim/physics/fsr.py", "creep_force",
     ["test_creep_terms_follow_the_force_and_add_only_while_loaded"]),
    ("creep state step", "ebraille_sim/physics/fsr.py", "creep_state_step",
     ["test_creep_terms_follow_the_force_and_add_only_while_loaded"]),
    ("held creep gain", "ebraille_sim/physics/fsr.py", "held_creep_gain",
     ["test_creep_terms_follow_the_force_and_add_only_while_loaded"]),
    ("hysteresis", "ebraille_sim/physics/fsr.py", "hysteresis", ["test_hysteresis_loading_branch_and_loop_width"]),
    ("divider", "ebraille_sim/physics/fsr.py", "divider_voltage", ["test_divider_is_paper_eq_1"]),
    ("divider inverse", "ebraille_sim/physics/fsr.py", "divider_conductance_s",
     ["test_divider_conductance_inverts_the_divider"]),
    ("ADC", "ebraille_sim/physics/fsr.py", "adc_code", ["test_adc_rounds_down_and_clips_at_the_rails"]),
    ("current-sense amplifier", "ebraille_sim/physics/current_sense.py", "amplifier_v",
     ["test_current_sense_amplifier_is_the_ina240_transfer"]),
    ("current-sense RC section", "ebraille_sim/physics/current_sense.py", "rc_step",
     ["test_current_sense_rc_section_is_the_exact_first_order_step"]),
    ("firmware current reading", "ebraille_sim/physics/current_sense.py", "firmware_current_a",
     ["test_firmware_current_reading_uses_the_nominal_transfer_and_its_zero"]),
    ("estimator step", "ebraille_sim/estimation/blockmodels.py", "estimator_step",
     ["test_estimator_step_equals_lfilter_and_interp_on_a_random_input"]),
    ("creep compensation", "ebraille_sim/estimation/firmware.py", "creep_compensated_v",
     ["test_creep_compensation_scales_the_conduction_path_by_the_gain_ratio"]),
    ("inverse hysteresis", "ebraille_sim/physics/fsr.py", "inverse_hysteresis",
     ["test_inverse_hysteresis_retraces_the_input_wherever_the_output_moves"]),
    ("hysteresis compensation", "ebraille_sim/estimation/firmware.py", "hysteresis_compensated_v",
     ["test_hysteresis_compensation_reads_the_loading_branch"]),
    ("hysteresis turn test", "ebraille_sim/estimation/firmware.py", "turn_tested_v",
     ["test_turn_test_reads_slow_and_fast_reversals_and_not_noise"]),
    ("hysteresis centring", "ebraille_sim/estimation/firmware.py", "centred_x",
     ["test_centring_relaxes_the_input_to_the_middle_of_the_blind_stretch_and_snaps_on_a_move"]),
    ("calibration table", "ebraille_sim/estimation/firmware.py", "table_calibrated_n",
     ["test_calibration_table_maps_each_bench_reading_onto_its_load"]),
    ("bench creep reading", "ebraille_sim/estimation/calibration.py", "bench_creep_per_decade",
     ["test_bench_creep_per_decade_recovers_the_units_creep_law"]),
    ("bench loop reading", "ebraille_sim/estimation/calibration.py", "bench_hysteresis_fraction",
     ["test_bench_loop_less_the_bench_creep_is_the_units_play_loop"]),
    ("push force bound", "ebraille_sim/physics/limits.py", "push_force_bound_n",
     ["test_push_force_bound_is_eta_km_n_over_r_less_friction_plus_weight"]),
    ("current for a push force", "ebraille_sim/physics/limits.py", "current_for_push_force_a",
     ["test_push_force_bound_is_eta_km_n_over_r_less_friction_plus_weight"]),
    ("speed from back-EMF", "ebraille_sim/physics/limits.py", "rack_speed_from_emf_m_per_s",
     ["test_speed_from_back_emf_and_impact_energy"]),
    ("impact energy", "ebraille_sim/physics/limits.py", "impact_energy_j",
     ["test_speed_from_back_emf_and_impact_energy"]),
    ("speed for an energy", "ebraille_sim/physics/limits.py", "speed_for_energy_m_per_s",
     ["test_speed_from_back_emf_and_impact_energy"]),
    ("pulp elastic energy", "ebraille_sim/physics/limits.py", "elastic_energy_j",
     ["test_pulp_energy_is_the_integral_of_the_elastic_law"]),
    ("absorbed impact energy", "ebraille_sim/physics/limits.py", "absorbed_energy_j",
     ["test_pulp_energy_is_the_integral_of_the_elastic_law"]),
    ("drive force for an impact", "ebraille_sim/physics/limits.py", "drive_force_for_impact_n",
     ["test_pulp_energy_is_the_integral_of_the_elastic_law"]),
    ("finger-pad contact area", "ebraille_sim/scenarios/legibility.py", "_contact_area_m2",
     ["test_legibility_contact_area_law_against_the_measured_finger_pad"]),
    ("contact radius", "ebraille_sim/scenarios/legibility.py", "_radius_of_area",
     ["test_legibility_contact_area_law_against_the_measured_finger_pad"]),
    ("electrode coverage", "ebraille_sim/scenarios/legibility.py", "_lens_area",
     ["test_legibility_lens_area_of_two_discs"]),
    ("electrode-skin impedance", "ebraille_sim/scenarios/legibility.py", "_impedance_at",
     ["test_legibility_impedance_falls_with_the_patch_pressure"]),
    ("stimulator current", "ebraille_sim/scenarios/legibility.py", "_current_a",
     ["test_legibility_stimulator_current_constant_current_and_voltage"]),
    ("strap transmission", "ebraille_sim/scenarios/disturbances.py", "strap_transmission",
     ["test_strap_transmission_is_the_relative_motion_of_base_excitation",
      "test_the_budget_takes_the_finger_motion_through_the_strap"]),
    ("slip peak force", "controllers/supervisor/motion.py", "slip_peak_force_n",
     ["test_slip_peak_force_without_the_mesh_is_the_hereditary_integral",
      "test_the_gear_mesh_gives_way_and_lowers_the_peak"]),
]

_RETURN = re.compile(r"^(\s*)return (.+)$")


def perturb_source(text: str, function: str, factor: str = FACTOR) -> tuple[str, int]:
    """``text`` with every ``return X`` of top-level ``function`` made ``return factor * (X)``."""
    tree = ast.parse(text)
    node = next((n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name == function), None)
    if node is None:
        raise ValueError(f"no function {function!r} in the source")
    lines = text.splitlines(keepends=True)
    count = 0
    for k in range(node.lineno - 1, node.end_lineno):
        m = _RETURN.match(lines[k].rstrip("\n"))
        if m:
            lines[k] = f"{m.group(1)}return {factor} * ({m.group(2)})\n"
            count += 1
    if count == 0:
        raise ValueError(f"{function!r} has no single-line return to perturb")
    return "".join(lines), count


def copy_tree(dest: pathlib.Path) -> None:
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", "*.nbi", "*.nbc")
    for name in COPY:
        src = ROOT / name
        if src.is_dir():
            shutil.copytree(src, dest / name, ignore=ignore)
        else:
            shutil.copy2(src, dest / name)


def run_tests(tree: pathlib.Path, tests) -> tuple[list[str], str]:
    env = dict(os.environ, PYTHONPATH=str(tree), NUMBA_CACHE_DIR=str(tree / ".numba_cache"))
    out = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--tb=no", "-rf",
                          *tests], cwd=tree, env=env, capture_output=True, text=True)
    failed = re.findall(r"^FAILED (\S+?)(?: - |$)", out.stdout, flags=re.M)
    return failed, out.stdout.strip().splitlines()[-1] if out.stdout.strip() else out.stderr[-300:]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--law", action="append", help="only these laws (by name; repeatable)")
    ap.add_argument("--tests", action="append", help=f"test files to run (default: {', '.join(DEFAULT_TESTS)})")
    ap.add_argument("--baseline", action="store_true", help="also run the unperturbed copy first")
    a = ap.parse_args(argv)
    tests = a.tests or list(DEFAULT_TESTS)
    laws = [law for law in LAWS if not a.law or law[0] in a.law]
    unknown = set(a.law or ()) - {law[0] for law in LAWS}
    if unknown:
        raise SystemExit(f"unknown law(s): {', '.join(sorted(unknown))}; known: {', '.join(x[0] for x in LAWS)}")
    rows, missed = [], []
    with tempfile.TemporaryDirectory(prefix="law_perturbation_") as tmp:
        if a.baseline:
            base = pathlib.Path(tmp) / "baseline"
            copy_tree(base)
            failed, summary = run_tests(base, tests)
            print(f"baseline (no change): {summary}", file=sys.stderr, flush=True)
            if failed:
                raise SystemExit(f"the unperturbed copy already fails: {', '.join(failed)}")
        for k, (law, rel, function, own) in enumerate(laws):
            t0 = time.perf_counter()
            tree = pathlib.Path(tmp) / f"law{k}"
            copy_tree(tree)
            path = tree / rel
            text, n_returns = perturb_source(path.read_text(), function)
            path.write_text(text)
            failed, summary = run_tests(tree, tests)
            names = [f.split("::")[-1] for f in failed]
            caught = [t for t in own if t in names]
            if not caught:
                missed.append(law)
            rows.append((law, f"{rel.split('/', 1)[1]}:{function}", len(failed), caught))
            print(f"{law}: {len(failed)} failed ({summary}) in {time.perf_counter() - t0:.0f} s",
                  file=sys.stderr, flush=True)
            shutil.rmtree(tree, ignore_errors=True)
    print(f"| law (return value x {FACTOR}) | file:function | failing tests | failing tests of that law |")
    print("|---|---|---|---|")
    for law, where, n, caught in rows:
        print(f"| {law} | `{where}` | {n} | {', '.join(caught) if caught else '**none: not caught**'} |")
    if missed:
        print(f"\nnot caught by their own tests: {', '.join(missed)}")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
