"""The stage registry is the one declaration of a stage: CLI, `artgs run` and the runner derive from it."""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import dataclass, fields

import pytest

from artgs.core import pipeline
from artgs.core.cli import app
from artgs.core.cli.options import add_options, build
from artgs.core.model import layout, registry
from artgs.core.model.errors import InputError
from artgs.core.model.progress import Progress
from artgs.core.model.registry import option


def _subcommands(parser) -> dict:
    action = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    return action.choices


def test_every_stage_is_a_subcommand_with_its_options_as_flags():
    subs = _subcommands(app.build_parser())
    for spec in registry.STAGES:
        assert spec.name in subs
        flags = {s for a in subs[spec.name]._actions for s in a.option_strings}
        for f in fields(spec.options):
            assert f"--{f.name.replace('_', '-')}" in flags
        assert pipeline.resolve(spec.run).__name__ == spec.run.split(":")[1]


def test_run_takes_every_stage_option_prefixed_and_shared_ones_once():
    run = _subcommands(app.build_parser())["run"]
    flags = [s for a in run._actions for s in a.option_strings]
    for spec in registry.STAGES:
        for f in fields(spec.options):
            name = f.name.replace("_", "-")
            if f.metadata.get("shared"):
                assert flags.count(f"--{name}") == 1
            else:
                assert f"--{spec.name}-{name}" in flags
    args = app.build_parser().parse_args(["run", "CAP", "--out", "O", "--device", "cpu",
                                          "--method", "vlm", "--reconstruct-iterations", "7"])
    assert args.shared__device == "cpu" and args.propose__method == "vlm"
    assert args.reconstruct__iterations == 7


def test_each_written_file_has_one_producer_and_inputs_come_before():
    seen: set[str] = set()
    for spec in registry.STAGES:
        assert set(spec.reads) <= seen, f"{spec.name} reads a file no earlier stage writes"
        assert not set(spec.writes) & seen, f"{spec.name} rewrites another stage's file"
        seen |= set(spec.writes)
    assert registry.producer_of(layout.SPLAT).name == "reconstruct"


def test_missing_input_names_the_stage_that_makes_it(tmp_path):
    with pytest.raises(InputError) as exc:
        registry.require(tmp_path, layout.SPLAT)
    assert str(tmp_path / layout.SPLAT) in str(exc.value) and "artgs reconstruct" in str(exc.value)


def test_options_dataclass_round_trips_through_flags():
    import argparse

    @dataclass
    class Opts:
        n: int = option(3, "a count")
        x: float | None = option(None, "a value")
        flag: bool = option(False, "a switch")
        names: list[str] | None = option(None, "names", choices=("a", "b"))
        mode: str = option("p", "a mode", choices=("p", "q"))

    p = argparse.ArgumentParser()
    add_options(p, Opts)
    assert build(Opts, p.parse_args([])) == Opts()
    got = build(Opts, p.parse_args(["--n", "5", "--x", "0.5", "--flag", "--names", "a",
                                    "--names", "b", "--mode", "q"]))
    assert got == Opts(n=5, x=0.5, flag=True, names=["a", "b"], mode="q")
    with pytest.raises(SystemExit):
        p.parse_args(["--mode", "z"])


def test_stage_subcommand_refuses_a_missing_input_with_exit_2(tmp_path):
    res = subprocess.run([sys.executable, "-m", "artgs", "propose", str(tmp_path), "--json"],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 2
    last = json.loads(res.stdout.splitlines()[-1])
    assert last["event"] == "error" and "artgs reconstruct" in last["message"]
    assert not any(tmp_path.iterdir())


def test_help_loads_no_torch():
    code = ("import sys; from artgs.core.cli.app import build_parser; build_parser(); "
            "from artgs.core import pipeline; print('torch' in sys.modules)")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.stdout.strip() == "False", res.stderr


def test_run_stage_records_figures_and_capture_only_after_success(tmp_path):
    from artgs.core.synth.generate import generate_object

    cap = generate_object(tmp_path / "cap", "drawer", seed=1, width=48, height=36,
                          static_views=6, steps=2)
    out = tmp_path / "out"
    figures = pipeline.run_stage("reconstruct", out, registry.ReconstructOptions(iterations=3),
                                 Progress("quiet"), capture=cap)
    report = layout.read_report(out)
    assert report["capture"] == str(cap.resolve())
    assert report["stages"]["reconstruct"]["iterations"] == figures["iterations"] == 3
    assert (out / layout.SPLAT).is_file()
