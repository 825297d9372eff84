"""The benchmarks' variants (core/bench/runs.py): robot-free, robot in view with its twin and
without (issue 16); their flags; bench-check when the motion route finds nothing. No benchmark
runs here: generation, proposals, optimisation and the check are stand-ins."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from artgs.core.bench import check as bench_check
from artgs.core.bench import runs
from artgs.core.bench.options import BenchCheckOptions, BenchOptimiseOptions
from artgs.core.bench.sets import BenchSet
from artgs.core.cli import main
from artgs.core.cli.app import build_parser
from artgs.core.cli.options import build
from artgs.core.model.errors import InputError, NothingFound
from artgs.core.model.joints import Articulation
from artgs.core.model.progress import QUIET


def test_robot_flags_parse():
    """bench-optimise --robot, bench-check --in-view-robot beside --robot (the checking robot)."""
    ns = build_parser().parse_args(["bench-optimise", "--robot", "xarm6", "--category", "cabinet"])
    assert build(BenchOptimiseOptions, ns).robot == "xarm6"
    ns = build_parser().parse_args(["bench-check", "--robot", "xarm6",
                                    "--in-view-robot", "franka_panda"])
    opts = build(BenchCheckOptions, ns)
    assert (opts.robot, opts.in_view_robot) == ("xarm6", "franka_panda")
    assert build(BenchCheckOptions, build_parser().parse_args(["bench-check"])).in_view_robot \
        is None


def test_opt_seed_reaches_the_optimisation(monkeypatch):
    """bench-optimise --opt-seed S: every capture's optimisation runs with seed S (default 0)."""
    from artgs.core.bench import optimise as bench_opt

    class Stop(Exception):
        pass

    def run_once(sets, run, *a):
        run(Path("cap"), Path("work"), runs.ROBOT_FREE)
        raise Stop

    def capture(cap, work, options, *a):
        seen.append(options.seed)

    assert build(BenchOptimiseOptions, build_parser().parse_args(["bench-optimise"])).opt_seed == 0
    seen: list[int] = []
    monkeypatch.setattr(bench_opt, "materialise_variants", lambda *a, **k: [])
    monkeypatch.setattr(bench_opt, "run_variants", run_once)
    monkeypatch.setattr(bench_opt, "bench_capture", capture)
    opts = build(BenchOptimiseOptions,
                 build_parser().parse_args(["bench-optimise", "--opt-seed", "3"]))
    with pytest.raises(Stop):
        bench_opt.bench_optimise(opts, QUIET)
    assert seen == [3]


def test_bad_robot_flags_exit_2(tmp_path, capsys):
    """An unknown robot, or a robot in view on a data: set, exits 2 naming the option."""
    with pytest.raises(SystemExit) as exc:
        main(["bench-optimise", "--robot", "ur5", "--quiet"])
    assert exc.value.code == 2 and "--robot" in capsys.readouterr().err
    assert main(["bench-check", "--data", str(tmp_path), "--in-view-robot", "xarm6",
                 "--quiet"]) == 2
    assert "in-view-robot" in capsys.readouterr().err


def test_plan_variants():
    assert runs.plan_variants(BenchSet("tight"), None) == [runs.ROBOT_FREE]
    variants = runs.plan_variants(BenchSet("realistic"), "xarm6")
    assert [(v.robot, v.robot_twin) for v in variants] == \
        [(None, True), ("xarm6", True), ("xarm6", False)]
    assert [v.title for v in variants] == ["robot-free", "xarm6 in view, with its twin",
                                           "xarm6 in view, without the twin (ablation)"]
    with pytest.raises(InputError, match="in_view_robot"):
        runs.plan_variants(BenchSet("data", Path(".")), "xarm6", "in_view_robot")


def test_materialise_once_per_robot_and_run(tmp_path, monkeypatch):
    """The robot's set is generated once for both of its variants; every capture of every
    variant is benchmarked into its own folder."""
    calls = []

    def fake_materialise(bset, work, **kwargs):
        calls.append((work.name, kwargs.get("robot")))
        return [work / "cabinet_00", work / "drawer_00"]

    monkeypatch.setattr(runs, "materialise", fake_materialise)
    variants = runs.plan_variants(BenchSet("tight"), "franka_panda")
    sets = runs.materialise_variants(BenchSet("tight"), tmp_path, variants, seed=0)
    assert calls == [("data", None), ("franka_panda", "franka_panda")]
    assert sets[1][1] is sets[2][1] and sets[0][1][0].parent.name == "data"
    done = runs.run_variants(sets, lambda cap, work, v: {"capture": cap.name, "work": work.name,
                                                         "twin": v.robot_twin},
                             tmp_path, QUIET, "bench-test")
    assert [[(r["work"], r["twin"]) for r in results] for _, results in done] == \
        [[("out0", True)] * 2, [("out1", True)] * 2, [("out2", False)] * 2]


def test_bench_check_optimises_when_nothing_proposed(tmp_path, monkeypatch):
    """The motion route finds nothing: proposals.json holds no joints, the optimise stage still
    runs (with the variant's twin setting) and its joints are checked."""
    import artgs.core.pipeline as pipeline
    import artgs.core.stages.propose.stage as propose_stage

    out = tmp_path / "out" / "cabinet_00"
    out.mkdir(parents=True)
    gt = Articulation([], {"category": "cabinet"})
    monkeypatch.setattr(bench_check, "prepare", lambda *a: (object(), gt, out))

    def nothing(*args, **kwargs):
        raise NothingFound("no moving parts")

    monkeypatch.setattr(propose_stage, "propose", nothing)
    stages = []
    monkeypatch.setattr(pipeline, "run_stage",
                        lambda name, o, options, progress, capture: stages.append(
                            (name, options.robot_twin)))
    checked = []

    def fake_check(o, urdf, robot):
        checked.append(json.loads((o / "proposals.json").read_text())["joints"])
        return {"door": {"success": len(checked) == 2}}

    monkeypatch.setattr(bench_check, "check_out", fake_check)
    variant = runs.Variant("franka_panda in view, without the twin (ablation)", "franka_panda",
                           False)
    r = bench_check.bench_capture(tmp_path / "cabinet_00", tmp_path / "out",
                                  BenchCheckOptions(), variant)
    assert checked == [[], []] and stages == [("optimise", False)]
    assert r["proposals"]["door"]["success"] is False and r["optimised"]["door"]["success"]


def test_bench_optimise_scores_an_optimisation_that_finds_nothing_as_missed(tmp_path,
                                                                            monkeypatch):
    """The optimise stage raises NothingFound (no part moves as far as the frames tell): the
    capture is scored, its true joint unmatched (AE 90, type wrong), in the main and basin runs,
    and the benchmark goes on; a stale articulation.json is not read as the answer."""
    import artgs.core.stages.optimise as optimise_stage
    from artgs.core.bench import optimise as bench_optimise
    from artgs.core.model.joints import Joint, write_articulation
    from artgs.core.model.registry import OptimiseOptions

    out = tmp_path / "out" / "door_00"
    out.mkdir(parents=True)
    truth = Joint("door", "revolute", [0, 0, 1], [0.3, 0.2, 0.0], (0.0, 1.5))
    gt = Articulation([truth], {"category": "door"})
    write_articulation(out / "articulation.json", gt)      # stale: must not count
    monkeypatch.setattr(bench_optimise, "prepare", lambda *a: (object(), gt, out))
    monkeypatch.setattr(bench_optimise, "motion_proposals",
                        lambda *a: Articulation([], {"source": "motion"}))
    calls = []

    def nothing(*args, **kwargs):
        calls.append(1)
        raise NothingFound("no moving part found")

    monkeypatch.setattr(optimise_stage, "optimise", nothing)
    r = bench_optimise.bench_capture(tmp_path / "door_00", tmp_path / "out", OptimiseOptions(),
                                     basin=1)
    assert len(calls) == 2
    for scores in (r["before"], r["after"], r["basin"]):
        assert [(s["joint"], s["pred"], s["type_ok"], s["ae"]) for s in scores] == \
            [("door", None, False, 90.0)]


def test_bench_check_counts_an_optimisation_that_finds_nothing_as_not_opened(tmp_path,
                                                                             monkeypatch):
    """Proposals exist, the optimisation then finds nothing (NothingFound): the optimised row is
    checked from OUT as the stage left it, and bench-check goes on."""
    import artgs.core.pipeline as pipeline

    out = tmp_path / "out" / "cabinet_00"
    out.mkdir(parents=True)
    monkeypatch.setattr(bench_check, "prepare",
                        lambda *a: (object(), Articulation([], {"category": "cabinet"}), out))
    monkeypatch.setattr(bench_check, "motion_proposals", lambda *a: None)

    def nothing(*args, **kwargs):
        raise NothingFound("no moving part found")

    monkeypatch.setattr(pipeline, "run_stage", nothing)
    results = iter([{"door": {"success": True}}, {"door": {"success": False}}])
    monkeypatch.setattr(bench_check, "check_out", lambda *a: next(results))
    r = bench_check.bench_capture(tmp_path / "cabinet_00", tmp_path / "out", BenchCheckOptions())
    assert r["proposals"]["door"]["success"] and not r["optimised"]["door"]["success"]


def test_benchmarks_default_to_the_reconstructed_splat():
    """The benchmarks' static splat is artgs run's (reconstructed until converged) unless
    --iterations says otherwise (0: the depth-initialised splat); the header names it."""
    assert build(BenchOptimiseOptions, build_parser().parse_args(["bench-optimise"])).iterations \
        is None
    assert build(BenchCheckOptions, build_parser().parse_args(
        ["bench-check", "--iterations", "0"])).iterations == 0
    assert runs.splat_label(None) == "reconstructed until converged"
    assert runs.splat_label(0) == "depth-initialised"
    assert runs.splat_label(500) == "reconstructed for 500 iterations"


def test_basin_starts_are_perturbed_and_of_the_wrong_type_in_turn():
    """Perturbed starts turn the axis 10-30 deg and move the line 5-15 cm; the wrong-type ones
    also flip the type and drop the states; the rate is given per kind of start."""
    from artgs.core.bench.optimise import basin_rate, perturbed
    from artgs.core.model.joints import Joint
    truth = [Joint("door", "revolute", [0, 0, 1], [0.3, 0.2, 0.0], (0.0, 1.5),
                   states={0: 0.0, 1: 1.0}),
             Joint("drawer", "prismatic", [1, 0, 0], [0.0, 0.0, 0.5], (0.0, 0.3),
                   states={0: 0.0, 1: 0.2})]
    rng = np.random.default_rng(0)
    for wrong in (False, True):
        for j, t in zip(perturbed(truth, rng, wrong_type=wrong), truth):
            turn = np.degrees(np.arccos(np.clip(j.axis @ t.axis, -1, 1)))
            d = j.origin - t.origin
            assert 10 - 1e-6 <= turn <= 30 + 1e-6
            assert 0.05 - 1e-9 <= np.linalg.norm(d - (d @ j.axis) * j.axis) <= 0.15 + 1e-9
            assert (j.type != t.type) == wrong and (j.states is None) == wrong
    results = [{"basin": [{"type_ok": True, "ae": 0.5, "oe": 0.5, "start": "perturbed"},
                          {"type_ok": False, "ae": 0.5, "oe": 0.5, "start": "wrong type"},
                          {"type_ok": True, "ae": 0.2, "oe": None, "start": "wrong type"}]}]
    assert basin_rate(results) == (2 / 3, 3)
    assert basin_rate(results, start="perturbed") == (1.0, 1)
    assert basin_rate(results, start="wrong type") == (0.5, 2)


def test_extra_joints_are_the_predictions_no_true_joint_took():
    """Two predictions for one door (a piece proposed twice) and a drawer never moved: one
    extra; the table shows it per category, before -> after."""
    from artgs.core.bench.optimise import _scores, extra_joints, format_table
    from artgs.core.bench.propose import summarize
    from artgs.core.model.joints import Joint
    truth = [Joint("door", "revolute", [0, 0, 1], [0.3, 0.2, 0.0], (0.0, 1.5))]
    pred = [Joint("a", "revolute", [0, 0, 1], [0.3, 0.2, 0.0], (0.0, 1.5)),
            Joint("b", "prismatic", [1, 0, 0], [0.0, 0.0, 0.5], (0.0, 0.3))]
    scores = _scores(pred, truth)
    assert [s["pred"] for s in scores] == ["a"] and extra_joints(pred, scores) == 1
    assert extra_joints(pred[:1], _scores(pred[:1], truth)) == 0
    assert extra_joints([], _scores([], truth)) == 0
    base = {"category": "door", "seconds": 1.0, "cpu_seconds": 1.0}
    before = summarize([{**base, "scores": scores, "extra": 1}])
    after = summarize([{**base, "scores": _scores(pred[:1], truth), "extra": 0}])
    assert [r["extra"] for r in before] == [1, 1]
    assert "1->0" in format_table(before, after).splitlines()[2]
