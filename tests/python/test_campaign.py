"""The random-rig campaign (tests/truth/campaign.py): its draws cover the ranges the issue sets, and
rigs of it that pass keep passing. The campaign itself (300 rigs, or the 30-seed subset with `--ci`)
is a benchmark, not a test: it prints the pass rate per class."""
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests" / "truth"))
import campaign  # noqa: E402

DRAWS = [campaign.draw(s) for s in range(1, 301)]


def test_the_draws_cover_every_range_and_class():
    for d in DRAWS:
        r = d["rig"]
        assert 0.2 * campaign.BENCH_J <= r["inertia"] <= 5 * campaign.BENCH_J, d["seed"]
        assert 0.3 * campaign.BENCH_K - 1e-9 <= r["stiffness_22c_equivalent"] <= 10 * campaign.BENCH_K + 1e-9
        assert r["rate_hz"] in campaign.RATES
        assert r["rate_hz"] >= 10 * r["natural_frequency_hz"] or r["rate_hz"] == campaign.RATES[-1], d["seed"]
        assert 5.0 <= r["duration_s"] <= 60.0
        assert 1e-5 <= r["noise"] <= 1e-3 and 1e3 <= r["counts_per_turn"] <= 1e5
        assert 0.0 <= r["jitter"] <= 0.2 and 0.0 <= r["dropout_s"] <= 0.5
        assert 1 <= len(r["temperatures"]) <= 4
        effects = set(d["expected"])
        assert not ({"asymmetric_friction"} & effects and {"link_damping", "constant_load"} & effects), d["seed"]
    ratios = [d["rig"]["natural_frequency_hz"] / max(d["rig"]["frequencies_hz"]) for d in DRAWS
              if d["rig"]["excitation"] == "sine"]
    assert min(ratios) < 4 and max(ratios) > 20, "natural frequencies from a few to many times the excitation"
    classes = {d["class"] for d in DRAWS}
    assert {"0 effects", "1 effect", "2 effects", "3 effects", "outside library"} <= classes, classes
    for key, share in [("jitter", 0.5), ("dropout_s", 1 / 3), ("drift_k", 1 / 3)]:
        seen = sum(d["rig"][key] > 0 for d in DRAWS) / len(DRAWS)
        assert abs(seen - share) < 0.1, (key, seen)
    assert {d["rig"]["excitation"] for d in DRAWS} == {"sine", "multisine", "steps"}
    drifts = [d["rig"] for d in DRAWS if d["rig"]["drift_k"]]
    assert all(1.0 <= r["drift_k"] <= 8.0 and 0.3 <= r["drift_time_constant_s"] / r["duration_s"] <= 3.0
               for r in drifts)
    assert {len(r["temperatures"]) for r in drifts} == {1, 2, 3, 4}
    # a thermal lag only behind a drift, on a share of the drifting rigs
    lagged = [d for d in DRAWS if "thermal_lag" in d["expected"]]
    assert all(d["rig"]["drift_k"] and 0 < d["rig"]["thermal_lag_s"] <= d["rig"]["duration_s"] for d in lagged)
    assert 0.1 * len(drifts) < len(lagged) < 0.5 * len(drifts), len(lagged)
    # an effect moves the link by 20× the noise floor (half a tenth of the amplitude where the floor is
    # that high) up to a tenth of the amplitude
    for d in DRAWS:
        if "backlash" in d["expected"]:
            width, a = d["expected"]["backlash"]["width_rad"], d["rig"]["amplitude_rad"]
            assert min(20 * d["floor"], 0.05 * a) * (1 - 1e-12) <= width <= 0.1 * a * (1 + 1e-12), d["seed"]


def test_the_ci_subset_is_fixed():
    seeds = campaign.ci_seeds()
    assert len(seeds) == campaign.CI_RIGS
    assert seeds == campaign.ci_seeds()
    assert all(campaign.draw(s)["samples"] <= campaign.CI_SAMPLES for s in seeds)


def test_an_equivalent_form_counts_only_where_the_report_declares_it_and_it_is_the_truths_set():
    found = [{"effect": "coulomb_friction", "parameters": {"torque_nm": 0.3}},
             {"effect": "constant_load", "parameters": {"torque_nm": -0.1}}]
    form = {"found": {"coulomb_friction": {"torque_nm": 0.3}, "constant_load": {"torque_nm": -0.1}},
            "equivalent": {"asymmetric_friction": {"coulomb_positive": 0.4, "coulomb_negative": 0.2}}}
    truth = {"asymmetric_friction": {}}
    effects, equivalent = campaign.in_truths_form({"added_effects": found, "equivalent_forms": [form]}, truth)
    assert equivalent and effects == form["equivalent"]
    # undeclared, or declared for a set the truth is not: the found set is judged as it stands
    effects, equivalent = campaign.in_truths_form({"added_effects": found, "equivalent_forms": []}, truth)
    assert not equivalent and set(effects) == {"coulomb_friction", "constant_load"}
    effects, equivalent = campaign.in_truths_form({"added_effects": found, "equivalent_forms": [form]},
                                                  {"asymmetric_friction": {}, "gravity": {}})
    assert not equivalent and set(effects) == {"coulomb_friction", "constant_load"}
    # the truth's own form is preferred when it was found as such
    effects, equivalent = campaign.in_truths_form({"added_effects": found, "equivalent_forms": [form]},
                                                  {"coulomb_friction": {}, "constant_load": {}})
    assert not equivalent


def test_each_missed_or_extra_effect_is_traced_through_the_chain_of_evidence():
    def attempt(effects, before, after, kept, stage="round", failed=None):
        a = {"effects": effects, "bic_before": before, "bic_after": after, "kept": kept, "stage": stage}
        return a if failed is None else dict(a, failed=failed)
    report = {
        "rounds": [
            {"ranking": [{"effect": e} for e in ("gravity", "backlash", "stribeck_friction", "thermal_lag")],
             "attempts": [attempt(["gravity"], -100.0, -200.0, True),
                          attempt(["backlash"], -200.0, -205.0, False),
                          attempt(["stribeck_friction"], -200.0, -260.0, False)]},
        ],
        "combinations": [attempt(["coulomb_friction", "link_damping"], -50.0, -100.0, True, "baseline")],
        "pruned_effects": [{"effect": "link_damping", "below_noise": True},
                           {"effect": "gravity", "below_noise": True, "replaced_by": "constant_load"}],
    }
    truth = {e: {} for e in ("gravity", "backlash", "stribeck_friction", "thermal_lag", "link_damping",
                             "asymmetric_friction")}
    found = {"coulomb_friction", "constant_load"}
    missed, extra = campaign.effect_fates(report, found, truth)
    assert missed == {
        "gravity": "pruned below the noise, replaced by constant_load",
        "link_damping": "pruned below the noise",
        "backlash": "refitted, its BIC never fell",
        "stribeck_friction": "refitted, its BIC fell, not kept",
        "thermal_lag": "ranked, never refitted",
        "asymmetric_friction": "never ranked",
    }
    assert extra == {"coulomb_friction": "kept at baseline", "constant_load": "the lighter form of gravity"}
    # a drive's refits name the tests they failed; the BIC's own failure is the other branch's
    drive = {"rounds": [{"ranking": [], "attempts": [
        attempt(["stribeck_friction"], -10.0, -90.0, False, failed=["wald", "visibility"]),
        attempt(["stribeck_friction", "asymmetric_friction"], -10.0, -95.0, False, failed=["bic", "wald"])]}]}
    missed, _ = campaign.effect_fates(drive, set(), {"stribeck_friction": {}})
    assert missed == {"stribeck_friction": "refitted, its BIC fell, not kept (visibility, wald)"}


def drive_report(effects, load, forms=()):
    return {"added_effects": [{"effect": k, "parameters": v} for k, v in effects.items()],
            "parameters": {"final": [{"name": "inertia", "value": 5.7e-5}, {"name": "constant_load", "value": load}]},
            "final": {"rmse": 1e-3}, "unexplained": False, "equivalent_forms": list(forms)}


def drive_rig(expected, load=None):
    params = {"inertia": 5.69e-5} if load is None else {"inertia": 5.69e-5, "constant_load": load}
    return {"expected": expected, "params": params, "floor": 1e-3, "rig": {"drive": "reference", "coulomb": 0.0014}}


def test_a_drive_is_judged_on_what_its_runs_show_of_friction_and_load():
    # drive rig 16's shape: asymmetric friction found with a load the truth does not have; while the
    # drive moves both act as F+ − L forward and F− + L back, which is what is judged
    levels = {"coulomb_positive": 0.00148, "coulomb_negative": 0.00132,
              "viscous_positive": 2.0e-4, "viscous_negative": 8.4e-5}
    truth = dict(levels, coulomb_positive=0.00206, coulomb_negative=0.00091)
    rig = drive_rig({"coulomb_friction": {"torque_nm": 0.00148}, "asymmetric_friction": truth})
    found = {"coulomb_friction": {"torque_nm": 0.0014}, "asymmetric_friction": levels}
    passed, why = campaign.score_drive(rig, drive_report(found, -0.00044))
    assert passed, why
    # the same levels without that load are another friction, and fail
    passed, why = campaign.score_drive(rig, drive_report(found, 0.0))
    assert not passed and "coulomb_positive" in " ".join(why), why
    # a truth with a load of its own: the truth is folded too
    rig = drive_rig({"coulomb_friction": {"torque_nm": 0.00148}, "asymmetric_friction": levels}, 0.0002)
    passed, why = campaign.score_drive(rig, drive_report(found, 0.0002))
    assert passed, why
    passed, why = campaign.score_drive(rig, drive_report(found, 0.0))
    assert not passed, why


def test_a_drive_is_judged_in_the_equivalent_form_it_declares():
    # asymmetric friction found where the truth is symmetric friction with a load: equivalent while it
    # moves, and declared so; judged in the truth's form only where the report declares it
    levels = {"coulomb_positive": 0.00158, "coulomb_negative": 0.00122,
              "viscous_positive": 1.0e-4, "viscous_negative": 1.02e-4}
    found = {"coulomb_friction": {"torque_nm": 0.0014}, "asymmetric_friction": levels}
    form = {"found": {"asymmetric_friction": levels},
            "equivalent": {"coulomb_friction": {"torque_nm": 0.0014}, "constant_load": {"torque_nm": -0.00018}}}
    rig = drive_rig({"coulomb_friction": {"torque_nm": 0.0014}}, -0.00018)
    passed, why = campaign.score_drive(rig, drive_report(found, 0.0, [form]))
    assert passed and rig["equivalent_form"], why
    passed, why = campaign.score_drive(rig, drive_report(found, 0.0))
    assert not passed and not rig["equivalent_form"] and "≠ truth" in " ".join(why), why
    # a viscous asymmetry symmetric friction cannot explain keeps the found form
    skewed = dict(levels, viscous_positive=2.0e-4)
    form["found"] = {"asymmetric_friction": skewed}
    passed, _ = campaign.score_drive(rig, drive_report(dict(found, asymmetric_friction=skewed), 0.0, [form]))
    assert not passed


# Rigs of the campaign that pass with today's loop (measured 2026-11-26; 18: a coarse encoder judged against the
# truth's replay, 43: the moving starts after gaps fitted; 156, 2026-11-29: a stiffness that grows with the
# angle, outside the library, flagged at 1.6× the floor the motor log's own error leaves, where the count's
# q/√12 had excused it; 161, 2026-11-30: steps whose motor band is no longer capped at three times their rms
# frequency, Coulomb friction and backlash without the constant load that stood in for the lost motion; 55,
# 2026-12-02: a thermal lag as long as its 16.9 s runs behind a 5 K heating, found once the lag is probed over
# the run's span; 10 and 156 drift in temperature since drift was drawn): a regression guard, not the campaign's
# pass rate (which the benchmark reports).
PASSING = [6, 10, 12, 18, 43, 55, 156, 161]


@pytest.mark.parametrize("seed", PASSING)
def test_rigs_that_pass_keep_passing(tmp_path, seed):
    result = campaign.run_rig(campaign.draw(seed), tmp_path, 120.0)
    assert result["passed"], result["why"]
    assert math.isfinite(result["seconds"])


def test_drift_leaves_every_other_draw_as_it_was(monkeypatch):
    # drift comes from a stream of its own: drawn from another, the drifts change and nothing else does
    def without_drift(d):
        args = list(d["truth_args"])
        if "--drift" in args:
            i = args.index("--drift")
            del args[i:i + 4]
        for i in [i for i, x in enumerate(args) if x.startswith("thermal_lag=")][::-1]:
            del args[i - 1:i + 1]
        return args, {k: v for k, v in d["expected"].items() if k != "thermal_lag"}
    monkeypatch.setattr(campaign, "DRIFT_STREAM", 2)
    other = [campaign.draw(s) for s in range(1, 61)]
    assert [d["rig"]["drift_k"] for d in other] != [d["rig"]["drift_k"] for d in DRAWS[:60]]
    for d, o in zip(DRAWS[:60], other):
        assert without_drift(d) == without_drift(o), d["seed"]
        assert d["samples"] == o["samples"]


# Two temperatures heating by 6 K through each 10 s run (47 → 53 and 57 → 63 °C): K and C change by up to 2.4×
# and 5× within a run (Table 2's E'' falls tenfold from 50 to 60 °C)
HEATING = ["--declare-inertia", "--seed", "3", "--temperatures", "50,60", "--frequencies", "1", "--stiffness", "20,12",
           "--damping", "0.12,0.05", "--duration", "10", "--noise", "1e-4", "--drift", "6", "--drift-time-constant", "4"]
HEATING_KC = [(20.0, 0.12), (12.0, 0.05)]


def calibrated(runs, out):
    """`thermovia calibrate` on a folder of runs: its report."""
    run = subprocess.run([str(campaign.THERMOVIA), "calibrate", str(runs), "--out", str(out), "--no-plots"],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    return json.loads((out / "report.json").read_text())


def test_a_drifting_thermocouple_is_followed_as_the_pcl_softens(tmp_path):
    # the loop drives its FMU with the logged thermocouple and must read each temperature's K and C at its
    # nominal one
    campaign.truth_model.main(["--out", str(tmp_path / "runs"), *HEATING])
    header = [l for l in (tmp_path / "runs" / "run_50C_1Hz.csv").read_text().splitlines() if not l.startswith("#")]
    temps = [float(l.split(",")[3]) for l in header[1:]]
    assert header[0].endswith(",temperature_c") and temps[0] == 47.0 and temps[-1] == 53.0
    assert all(b >= a for a, b in zip(temps, temps[1:]))
    report = calibrated(tmp_path / "runs", tmp_path / "calibration")
    assert report["added_effects"] == [], report["added_effects"]
    for g, (k, c) in zip(report["identified"], HEATING_KC):
        assert abs(g["stiffness"] / k - 1) < 0.02 and abs(g["damping"] / c - 1) < 0.02, g
    floor = math.sqrt(1e-4 ** 2 + campaign.truth_model.ENCODER_QUANTUM ** 2 / 12)
    assert report["final"]["rmse_rad"] < 1.1 * floor, report["final"]["rmse_rad"] / floor
    # the same runs without their thermocouple column (steady at the nominal temperature) fit far worse
    (tmp_path / "steady").mkdir()
    for f in (tmp_path / "runs").glob("*.csv"):
        lines = f.read_text().splitlines()
        (tmp_path / "steady" / f.name).write_text(
            "\n".join(l if l.startswith("#") else l.rsplit(",", 1)[0] for l in lines) + "\n")
    steady = calibrated(tmp_path / "steady", tmp_path / "steady-calibration")
    assert steady["baseline"]["rmse_rad"] > 3 * floor, steady["baseline"]["rmse_rad"] / floor


def test_a_thermal_lag_behind_a_drifting_thermocouple_is_found(tmp_path):
    # the same heating, the PCL 1.5 s behind the thermocouple (the truth's closed-form first-order lag):
    # the loop must add the lag and read its time constant, with K and C still at their nominal temperatures
    campaign.truth_model.main(["--out", str(tmp_path / "runs"), *HEATING, "--effect", "thermal_lag=1.5"])
    report = calibrated(tmp_path / "runs", tmp_path / "calibration")
    assert [e["effect"] for e in report["added_effects"]] == ["thermal_lag"], report["added_effects"]
    lag = report["added_effects"][0]["parameters"]["time_constant_s"]
    assert abs(lag / 1.5 - 1) < 0.1, lag
    for g, (k, c) in zip(report["identified"], HEATING_KC):
        assert abs(g["stiffness"] / k - 1) < 0.02 and abs(g["damping"] / c - 1) < 0.02, g
    assert report["final"]["rmse_rad"] < 0.6 * report["baseline"]["rmse_rad"]


def test_coulomb_friction_is_not_read_as_hysteretic_damping(tmp_path):
    # campaign rig 180, shortened: sines at two frequencies per temperature through a viscous
    # transmission, and Coulomb friction. Its dissipation per cycle falls with frequency as hysteretic
    # damping's does, so the baseline chose that law, and Coulomb friction refitted under it alone left
    # too much structure to earn its place: nothing was added, 8x the floor (the loop before 2026-11-29)
    args = ["--declare-inertia", "--seed", "180", "--excitation", "sine", "--temperatures", "40,60",
            "--frequencies", "1.718,3.436", "--stiffness", "24.2,6.05", "--damping", "0.2185,0.109",
            "--inertia", "0.00703", "--amplitude", "0.265", "--duration", "5", "--rate", "5000",
            "--noise", "1.56e-4", "--quantum", "1.41e-3", "--jitter", "0", "--dropout", "0",
            "--effect", "coulomb_friction=0.0644"]
    campaign.truth_model.main(["--out", str(tmp_path / "runs"), *args])
    run = subprocess.run([str(campaign.THERMOVIA), "calibrate", str(tmp_path / "runs"), "--out",
                          str(tmp_path / "calibration"), "--no-plots"], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    report = json.loads((tmp_path / "calibration" / "report.json").read_text())
    assert [e["effect"] for e in report["added_effects"]] == ["coulomb_friction"], report["added_effects"]
    assert report["damping_law"]["chosen"] == "viscous", report["damping_law"]
    coulomb = report["added_effects"][0]["parameters"]["torque_nm"]
    assert abs(coulomb / 0.0644 - 1) < 0.1, coulomb
    for g, (k, c) in zip(report["identified"], [(24.2, 0.2185), (6.05, 0.109)]):
        assert abs(g["stiffness"] / k - 1) < 0.1 and abs(g["damping"] / c - 1) < 0.1, g


def test_friction_is_refitted_from_a_transmission_a_link_damper_emptied(tmp_path):
    # campaign rig 185 (asymmetric friction and gravity, one temperature, one sine, jitter and a dropout):
    # a link damping came in first and took the transmission's damping (C on its lower bound). A group on a
    # bound started every later refit from the table's transmission, and every friction refitted beside the
    # damper ended its screening iterations above the model it extended: nothing more came in, 5.9x the
    # floor, unexplained (the loop before 2026-11-30, evening). Where the table's start ends above the current
    # model, the current transmission's start is refitted too. The rig still fails the campaign (a load and
    # gravity at an offset stand in for the friction's asymmetry, and the damper stays): this guards the fit
    result = campaign.run_rig(campaign.draw(185), tmp_path, 120.0)
    assert "coulomb_friction" in result["added"] or "asymmetric_friction" in result["added"], result["added"]
    assert result["ratio"] < 1.5, result["why"]


def test_a_sticking_link_after_a_gap_is_searched_again_from_its_final_starts(tmp_path):
    # fresh campaign rig 655: Coulomb friction 0.46 N·m and a Stribeck excess 0.20 N·m over 0.058 rad/s on a
    # soft, light link at 0.21 Hz, each run split by a 0.26 s dropout; the link sticks and slips. The baseline,
    # without friction, started the segment after one gap at -0.50 rad/s where the link sticks: from there even
    # the truth's parameters fit at 81x the floor, and the search ended with Coulomb friction alone at 33x
    # (the loop before 2026-12-04). With the starts the final effects fit, the search runs again and finds both.
    result = campaign.run_rig(campaign.draw(655), tmp_path, 120.0)
    assert result["passed"], result["why"]
    report = json.loads((tmp_path / "rig_655" / "calibration" / "report.json").read_text())
    assert report["searched_again"]["from_round"] >= 2, report["searched_again"]


def test_a_backlash_standing_in_for_friction_is_refitted_without(tmp_path):
    # fresh campaign rig 659: asymmetric friction 4.75 / 5.20 N·m on a 117 N·m/rad link. The search kept a
    # 33 mrad backlash beside the friction, whose levels it held 36-40 % low; the backward check never refitted
    # without it, its linearised removal reading as plainly needed (the loop before 2026-12-04, night). Refitted
    # without it, the friction reaches the truth's levels and the BIC falls.
    result = campaign.run_rig(campaign.draw(659), tmp_path, 120.0)
    assert result["passed"], result["why"]
    report = json.loads((tmp_path / "rig_659" / "calibration" / "report.json").read_text())
    backlash = [p for p in report["pruned_effects"] if p["effect"] == "backlash"]
    assert backlash and not backlash[0]["below_noise"], report["pruned_effects"]
    assert backlash[0]["bic_without"] < backlash[0]["bic_with"], backlash


DRIVE_DRAWS = [campaign.draw_drive(s) for s in range(1, 201)]


def test_the_drive_truth_takes_every_drawn_rigs_arguments():
    # a negative load in exponent notation ("-5e-05") read as an option ended the 300-rig benchmark
    for d in DRIVE_DRAWS:
        a = campaign.drive_truth.parse_args(["--out", "unused", *d["truth_args"]])
        assert a.load == d["params"].get("constant_load", 0.0)


def test_the_drive_draws_cover_servos_to_linear_axes():
    rotary = [d["rig"]["inertia"] for d in DRIVE_DRAWS if d["rig"]["axis"] == "rotary"]
    linear = [d["rig"]["inertia"] for d in DRIVE_DRAWS if d["rig"]["axis"] == "linear"]
    assert min(rotary) < 3e-5 and max(rotary) > 3e-3 and all(1e-5 <= j <= 1e-2 for j in rotary)
    assert min(linear) < 3 and max(linear) > 30 and all(1 <= m <= 100 for m in linear)
    assert {d["rig"]["drive"] for d in DRIVE_DRAWS} == {"motor_torque", "reference"}
    assert {d["rig"]["extra"] for d in DRIVE_DRAWS} == {"none", "stribeck", "asymmetric"}
    for d in DRIVE_DRAWS:
        r = d["rig"]
        assert r["rate_hz"] in campaign.RATES and 2 <= len(r["durations_s"]) <= 8
        assert all(5.0 <= t <= 30.0 for t in r["durations_s"])
        assert 0.0 <= r["jitter"] <= 0.2 and 0.0 <= r["dropout_s"] <= 0.5
        assert "coulomb_friction" in d["expected"]


# Drive rigs that pass with today's loop (measured 2026-11-26): a rotary servo and a linear axis on their
# logged torque, a servo with Stribeck friction, and two position servos replayed through their controller
# (one with a constant load); 55 (2026-11-28): torque steps whose open-loop simulation drifts, judged in the
# equation error (flagged unexplained when its sign check read the simulated position); 44 (2026-12-02): a linear
# axis under a stiff loop whose Stribeck excess the positions hide and the logged force shows.
PASSING_DRIVES = [8, 14, 20, 2, 19, 55, 44]


@pytest.mark.parametrize("seed", PASSING_DRIVES)
def test_drive_rigs_that_pass_keep_passing(tmp_path, seed):
    result = campaign.run_rig(campaign.draw_drive(seed), tmp_path, 120.0)
    assert result["passed"], result["why"]


def test_the_reference_driven_rate_is_split_at_the_position_floor(capsys):
    def result(offset, passed):
        return {"class": "drive rotary, reference", "passed": passed, "rig": {"friction_offset_floors": offset}}
    torque_driven = {"class": "drive rotary, torque", "passed": False, "rig": {}}
    campaign.print_offset_breakdown([result(0.2, False), result(0.99, True), result(1.0, True), result(7.0, False),
                                     torque_driven])
    lines = capsys.readouterr().out.splitlines()
    assert lines == ["  reference-driven, friction's offset Fc/kp under the position floor: 1/2 passed",
                     "  reference-driven, friction's offset Fc/kp over the position floor: 1/2 passed"]


def test_the_pass_rate_is_printed_per_class_in_the_bins_order(capsys):
    def result(rate, passed):
        return {"class": "1 effect", "passed": passed, "rig": {"rate_hz": rate}}
    campaign.print_classes([result(5000, False), result(200, True), result(1000, True), result(400, False)],
                           "title", [("rate", lambda r: campaign.bins(r["rig"]["rate_hz"], (500, 2000), " Hz")),
                                     ("missing", lambda r: r["rig"]["jitter"])])
    lines = capsys.readouterr().out.splitlines()
    assert lines == ["", "title", "  rate: ≤ 500 Hz 1/2, ≤ 2000 Hz 1/1, > 2000 Hz 0/1", "  missing: unknown 2/4"]


def test_the_median_wall_time_is_printed_per_class(capsys):
    def result(drift, seconds):
        return {"class": "1 effect", "passed": True, "seconds": seconds, "rig": {"drift_k": drift}}
    campaign.print_classes([result(0.0, 4.0), result(3.0, 60.0), result(0.0, 10.0), result(5.0, 90.0),
                            result(2.0, 20.0), result(0.0, 2.0)],
                           "title", [("temperature", lambda r: "drifting" if r["rig"]["drift_k"] else "steady"),
                                     ("missing", lambda r: r["rig"]["jitter"])], campaign.median_time)
    lines = capsys.readouterr().out.splitlines()
    assert lines == ["", "title", "  temperature: drifting 60.0 s (3), steady 4.0 s (3)",
                     "  missing: unknown 15.0 s (6)"]


def test_a_torque_multisine_reaches_the_rigs_peak_speed(tmp_path):
    # drive rig 13's body (inertia-dominated at the multisine's 0.3-5 Hz): a torque peak of the peak
    # speed's friction alone reached 9 of its 143 rad/s, below its 15 rad/s Stribeck speed
    args = ["--axis", "rotary", "--drive", "motor_torque", "--excitation", "multisine", "--inertia", "4.29e-05",
            "--viscous", "9.7e-06", "--coulomb", "2.34e-4", "--stribeck", "1.44e-4", "15.1", "--speed", "143",
            "--runs", "1", "--duration", "10", "--rate", "500", "--noise", "1e-6", "--quantum", "0", "--seed", "13"]
    campaign.drive_truth.main(["--out", str(tmp_path), *args])
    lines = [l for l in (tmp_path / "run_0.csv").read_text().splitlines() if not l.startswith("#")]
    rows = np.array([[float(x) for x in l.split(",")[:2]] for l in lines[1:]])
    speed = np.abs(np.diff(rows[:, 1]) / np.diff(rows[:, 0]))
    assert 0.5 * 143 < speed.max() < 2 * 143, speed.max()
