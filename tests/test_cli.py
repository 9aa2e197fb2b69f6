"""Command-line conventions: --help and --version without JAX, --json keeps stdout to one JSON object, --quiet,
the exit status of each outcome (0, 1, 2, 3, 130), a prior of one's own (prior new, fit --prior, --label)."""

from __future__ import annotations

import inspect
import json
import subprocess
import sys
from pathlib import Path

import pytest

import peano_bayes
from peano_bayes import bundled
from peano_bayes.analysis.ranking import CRITERIA
from peano_bayes.app import pipeline
from peano_bayes.app.cli import main
from peano_bayes.app.commands import COMMANDS
from peano_bayes.data import load, save
from peano_bayes.defaults import DEFAULT_SAMPLE_ALL
from peano_bayes.errors import PeanoBayesInputError
from peano_bayes.inference.prior_files import load_prior
from peano_bayes.inference.sample import SamplingInterrupted
from peano_bayes.rig import RigSimulationError


def test_help_of_every_command_and_version_import_no_jax():
    script = (
        "import sys, contextlib, io\n"
        "from peano_bayes.app.cli import build_parser\n"
        "from peano_bayes.app.commands import COMMANDS\n"
        "parser = build_parser()\n"
        "for argv in (['--help'], ['--version'], *[[name, '--help'] for name in COMMANDS], ['prior', '-h']):\n"
        "    with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):\n"
        "        parser.parse_args(argv)\n"
        "print(sorted(m for m in sys.modules if m == 'jax' or m.startswith('jax.')))\n"
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_version(capsys):
    with pytest.raises(SystemExit) as stop:
        main(["--version"])
    assert stop.value.code == 0
    assert capsys.readouterr().out.strip() == f"peano-bayes {peano_bayes.__version__}"


def test_json_output_is_the_only_thing_on_stdout(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)  # a bundled code resolves from anywhere
    assert main(["check", "TP", "--json"]) == 0
    captured = capsys.readouterr()
    report = json.loads(captured.out)  # the whole of stdout is one JSON object
    assert report["file"] == str(bundled.dataset_path("TP"))
    assert "TP (60 um LDPE) - valid" in captured.err  # the human summary went to stderr


def test_check_warns_of_pressures_past_what_the_answers_are_offered_for(tmp_path, capsys):
    """Valid data up to the format's 2000 kPa pass ``check``; above the 1000 kPa to which metrics, recommend and
    demo predict, ``check`` says so (stderr, and ``warnings`` under --json)."""
    valid = Path(__file__).parent / "malformed" / "valid.csv"
    lines = valid.read_text().splitlines()
    lines[1] = lines[1].replace(",200.0,", ",1500.0,")
    assert lines[1].split(",")[4] == "1500.0"
    (tmp_path / "high.csv").write_text("\n".join(lines) + "\n")
    (tmp_path / "high.toml").write_text(valid.with_suffix(".toml").read_text())
    assert main(["check", str(tmp_path / "high.csv"), "--json"]) == 0
    captured = capsys.readouterr()
    (warning,) = json.loads(captured.out)["warnings"]
    assert "pressures reach 1500 kPa, above the 1000 kPa" in warning and f"WARNING: {warning}" in captured.err
    assert main(["check", "TP", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["warnings"] == []


def test_quiet_prints_nothing_on_success(capsys):
    assert main(["check", "TP", "--quiet"]) == 0
    assert capsys.readouterr().out == ""
    assert main(["check", "TP", "--quiet", "--json"]) == 0  # the JSON object alone, and no summary on stderr
    captured = capsys.readouterr()
    assert json.loads(captured.out)["valid"] is True and captured.err == ""


@pytest.fixture
def own_muscle(tmp_path):
    """A small rig file of a material code with no bundled prior ("VM"): two of TPC's load cycles."""
    import dataclasses

    data = load(bundled.dataset_path("TPC"))
    runs = tuple(r for r in data.runs if r.test == "load_cycle")[:2]
    relabelled = dataclasses.replace(data, runs=runs, material=dataclasses.replace(data.material, code="VM"))
    return save(relabelled, tmp_path / "VM_first.csv")


def test_a_fit_says_which_asked_for_tests_the_file_lacks(own_muscle, tmp_path):
    """The default tests are the load cycles, blocking and stroke; a file of load cycles alone is fitted on them,
    and the log says so (here the fit then stops at its missing prior, before any work)."""
    lines = []
    with pytest.raises(PeanoBayesInputError, match="'VM'"):
        pipeline.infer(load(own_muscle), tmp_path / "out", log=lines.append)
    assert "VM: the file has no blocking, stroke runs; fitting load_cycle only" in lines


@pytest.mark.parametrize("sample_all", [False, True])
def test_a_fit_says_which_shape_constants_it_holds(tmp_path, monkeypatch, sample_all):
    """The log names the shape constants held at nominal (every interval is conditional on them) and how to
    sample them; with ``--sample-all`` nothing is said (here the fit stops at its least squares, before any work)."""

    def stop(*args, **kwargs):
        raise RuntimeError("stopped before the least squares")

    monkeypatch.setattr(pipeline, "least_squares", stop)
    lines = []
    with pytest.raises(RuntimeError, match="stopped before"):
        pipeline.infer(load(bundled.dataset_path("TP")), tmp_path / "out", log=lines.append, sample_all=sample_all)
    (line,) = [line for line in lines if "parameters sampled" in line]
    held = (
        "; shape constants held at nominal, not sampled: length_fraction = 0.8, bending_exponent = 6, "
        "extension_rate = 50"
    )
    assert ("shape constants held" in line) is not sample_all, line
    assert sample_all or (held in line and line.endswith("(--sample-all samples them)")), line


@pytest.mark.parametrize(
    "flag, sampled", [([], DEFAULT_SAMPLE_ALL), (["--sample-all"], True), (["--no-sample-all"], False)]
)
def test_fit_samples_the_shape_constants_as_told_else_by_default(own_muscle, tmp_path, monkeypatch, flag, sampled):
    """The command line and the Python API share one default, :data:`~peano_bayes.defaults.DEFAULT_SAMPLE_ALL`."""
    assert inspect.signature(pipeline.infer).parameters["sample_all"].default is DEFAULT_SAMPLE_ALL
    seen = []

    def infer(data, out_dir, **kwargs):
        seen.append(kwargs["sample_all"])
        return _fake_infer(True)(data, out_dir, **kwargs)

    monkeypatch.setattr(pipeline, "infer", infer)
    assert main(["fit", str(own_muscle), "--out", str(tmp_path / "out"), "--prior", "TPC", *flag]) == 0
    assert seen == [sampled]


def test_fit_of_an_unknown_material_without_a_prior_names_the_option(own_muscle, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["fit", str(own_muscle), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "'VM'" in err and "--prior FILE.toml" in err and "prior new --like" in err
    assert "Traceback" not in err
    assert not out.exists()


@pytest.mark.parametrize("label", ["../escape", "a/b", "", " padded"])
def test_a_label_that_is_not_a_folder_name_is_bad_input(own_muscle, tmp_path, capsys, label):
    out = tmp_path / "out"
    argv = ["fit", str(own_muscle), "--out", str(out), "--prior", "TPC", "--label", label]
    assert main(argv) == 2
    assert "--label" in capsys.readouterr().err
    assert not out.exists()


def test_prior_new_writes_the_like_materials_prior_to_edit(tmp_path, capsys):
    path = tmp_path / "VM.toml"
    assert main(["prior", "new", "--like", "TPC", "--out", str(path), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["material"] == "VM"  # from the file's stem
    written, like = load_prior(path), load_prior("TPC")
    assert written.names == like.names
    assert written.config == like.config
    assert all(dict(written.marginals[n].spec) == dict(like.marginals[n].spec) for n in like.names)
    assert written.files[-1] == path and written.files[-2] == like.files[-1]  # it extends TPC's own file
    # An existing file is not overwritten, and a bad code writes nothing.
    before = path.read_text()
    assert main(["prior", "new", "--like", "TPC", "--out", str(path)]) == 2
    assert path.read_text() == before
    assert main(["prior", "new", "--like", "XX", "--out", str(tmp_path / "x.toml")]) == 2
    assert not (tmp_path / "x.toml").exists()
    assert main(["prior", "new", "--like", "TPC", "--out", str(tmp_path / "x.txt")]) == 2


def _fake_infer(outcome):
    def infer(data, out_dir, **kwargs):
        if isinstance(outcome, BaseException):
            raise outcome
        conv = {"converged": outcome, "problems": [] if outcome else ["R-hat misses its target"], "rhat": {"a": 1.0},
                "ess_bulk": {"a": 2000.0}}
        return {"material": data.material.code, "label": kwargs.get("label") or "VM_first", "convergence": conv,
                "steps": 40, "timings_s": {}, "prior": kwargs.get("prior")}

    return infer


@pytest.mark.parametrize(
    "outcome, status",
    [
        (True, 0),
        (False, 3),  # finished, not converged
        (RigSimulationError("the solver missed its tolerance"), 1),  # a computation failed, not the input
        (KeyboardInterrupt(), 130),
        (SamplingInterrupted("stopped at step 80; state saved in s.npz: run the same command with --resume"), 130),
        (PeanoBayesInputError("bad thing"), 2),
    ],
)
def test_exit_status_of_each_outcome(own_muscle, tmp_path, capsys, monkeypatch, outcome, status):
    monkeypatch.setattr(pipeline, "infer", _fake_infer(outcome))
    argv = ["fit", str(own_muscle), "--out", str(tmp_path / "out"), "--prior", "TPC", "--json"]
    assert main(argv) == status
    captured = capsys.readouterr()
    if status in (0, 3):
        report = json.loads(captured.out)
        assert report["converged"] is (status == 0) and report["label"] == "VM_first"
    else:  # the one JSON object says why it stopped
        assert json.loads(captured.out) == {"error": captured.err.strip().split(": ", 1)[1], "exit_status": status}
        assert "Traceback" not in captured.err
        if isinstance(outcome, SamplingInterrupted):  # where the state is and how to go on
            assert "interrupted: stopped at step 80; state saved in s.npz" in captured.err
            assert "--resume" in captured.err


def test_every_command_is_registered_once_with_help():
    assert {"demo", "check", "simulate", "fit", "run", "prior", "metrics", "rank", "recommend", "discover"} <= set(
        COMMANDS
    )
    assert all(c.help for c in COMMANDS.values())


def test_prior_new_like_a_prior_file_of_ones_own_extends_it_by_its_relative_path(tmp_path, capsys):
    (tmp_path / "p").mkdir()
    (tmp_path / "sim").mkdir()
    first = tmp_path / "p" / "mine.toml"
    assert main(["prior", "new", "--like", "TPC", "--out", str(first)]) == 0
    second = tmp_path / "sim" / "next.toml"
    assert main(["prior", "new", "--like", str(first), "--out", str(second)]) == 0
    assert 'extends = "../p/mine.toml"' in second.read_text()
    chain = load_prior(second).files
    assert chain[-1] == second and chain[-2].resolve() == first.resolve()
    capsys.readouterr()
    assert main(["prior", "new", "--like", "TPC", "--out", str(tmp_path / "x.toml"), "--material", " "]) == 2
    assert "--material" in capsys.readouterr().err and not (tmp_path / "x.toml").exists()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["check", "."], "a directory, not a dataset"),
        (["check", "{tmp}/notes.txt"], "not a dataset file"),
        (["demo", "--pressures-kpa", "-5"], "--pressures-kpa must be a pressure in kPa"),
        (["demo", "--pressures-kpa", "nan"], "--pressures-kpa must be a pressure in kPa"),
        (["metrics", "{tmp}", "--pressure-kpa", "200000"], "at most 1000"),
        (["discover", "TP", "--out", "{tmp}/d", "--base", ""], "--base: expected effect names"),
        (["recommend", "--spec", "{tmp}/spec.toml", "--mount-compliance", "5"], "from 0 to 0.1"),
    ],
)
def test_bad_arguments_exit_2_with_one_line_naming_them(tmp_path, capsys, argv, message):
    (tmp_path / "notes.txt").write_text("not a dataset")
    before = sorted(tmp_path.rglob("*"))
    assert main([a.format(tmp=tmp_path) for a in argv]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1 and "Traceback" not in err
    assert sorted(tmp_path.rglob("*")) == before  # nothing written


def test_a_path_that_cannot_be_written_as_asked_is_bad_input_without_a_traceback(tmp_path, capsys):
    for code in ("TP", "P"):
        (tmp_path / code).mkdir()
        draws = {c: [1.0, 2.0, 3.0] for c in CRITERIA}
        (tmp_path / code / "metrics.json").write_text(json.dumps({"material": code, "draw_values": draws}))
    taken = tmp_path / "taken"
    taken.write_text("a file, not a folder")
    assert main(["rank", str(tmp_path / "TP"), str(tmp_path / "P"), "--out", str(taken)]) == 2
    err = capsys.readouterr().err
    assert str(taken) in err and err.count("\n") == 1 and "Traceback" not in err
    assert taken.read_text() == "a file, not a folder"


def test_material_codes_are_case_blind_on_the_command_line(capsys):
    assert main(["check", "tp", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["file"] == str(bundled.dataset_path("TP"))


def test_a_reader_that_closes_the_pipe_ends_the_command_quietly(monkeypatch, capsys):
    class ClosedPipe:
        def write(self, text):
            raise BrokenPipeError(32, "Broken pipe")

        def flush(self):
            raise BrokenPipeError(32, "Broken pipe")

        def fileno(self):
            raise OSError("no file descriptor")

    monkeypatch.setattr(sys, "stdout", ClosedPipe())
    assert main(["check", "TP", "--json"]) == 1
    assert "Traceback" not in capsys.readouterr().err


def test_fit_many_refuses_a_bad_prior_or_walker_count_before_writing(own_muscle, tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text(
        '[meta]\nmaterial = "VM"\nextends = "default.toml"\n[parameters.length_fraction]\n'
        'distribution = "truncnormal"\nmean = 0.7\nsd = -1.0\nlow = 0.3\nhigh = 1.0\nunit = "-"\n'
        'provenance = "a test"\n'
    )
    out = tmp_path / "many"
    assert main(["fit-many", str(own_muscle), "--prior", str(bad), "--out", str(out)]) == 2
    assert "'sd' must be positive" in capsys.readouterr().err and not out.exists()
    assert main(["fit-many", str(own_muscle), "--prior", "TPC", "--walkers", "4", "--out", str(out)]) == 2
    assert "walkers" in capsys.readouterr().err and not out.exists()


def test_json_output_is_standard_json_with_null_where_a_value_is_not_finite(monkeypatch, capsys):
    import numpy as np

    from peano_bayes.app.commands import Command

    result = {"nan": float("nan"), "many": [np.float64("inf"), 1.5], "narrow": np.float32(2.5), "n": 3}
    monkeypatch.setitem(COMMANDS, "demo", Command("a stand-in", lambda args: result))
    assert main(["demo", "--json"]) == 0

    def refuse(constant):
        raise ValueError(f"not standard JSON: {constant}")

    parsed = json.loads(capsys.readouterr().out, parse_constant=refuse)
    assert parsed == {"nan": None, "many": [None, 1.5], "narrow": 2.5, "n": 3}


def test_a_dataset_stem_beside_its_result_folder_still_names_the_dataset(own_muscle, capsys):
    stem = own_muscle.with_suffix("")
    stem.mkdir()  # what 'fit my --out .' makes next to my.csv
    assert main(["check", str(stem), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["file"] == str(own_muscle)


def test_prior_new_refuses_a_prior_that_would_extend_itself_or_a_stand_in(tmp_path, capsys):
    own = tmp_path / "PR.toml"
    assert main(["prior", "new", "--like", "PR", "--out", str(own)]) == 2  # 'extends = "PR.toml"' finds itself
    assert "would extend itself" in capsys.readouterr().err and not own.exists()
    mine = tmp_path / "mine.toml"
    assert main(["prior", "new", "--like", "TPC", "--out", str(mine)]) == 0
    before = mine.read_text()
    assert main(["prior", "new", "--like", str(mine), "--out", str(mine), "--force"]) == 2
    assert "would extend itself" in capsys.readouterr().err and mine.read_text() == before
    own.write_text(before)  # a file of one's own named like the bundled PR.toml
    assert main(["prior", "new", "--like", "PR", "--out", str(tmp_path / "other.toml")]) == 2
    assert "would stand in for the bundled PR.toml" in capsys.readouterr().err
    assert not (tmp_path / "other.toml").exists()
    # nor one that would close a cycle: next.toml extends mine.toml, which is to be rewritten to extend next.toml
    following = tmp_path / "next.toml"
    assert main(["prior", "new", "--like", str(mine), "--out", str(following)]) == 0
    assert main(["prior", "new", "--like", str(following), "--out", str(mine), "--force"]) == 2
    assert "is in the chain of the prior it starts from" in capsys.readouterr().err and mine.read_text() == before


def test_an_os_error_that_names_no_path_is_a_failed_computation(monkeypatch, capsys):
    from peano_bayes.app.commands import Command

    def lost(args):
        raise ConnectionRefusedError(111, "Connection refused")

    monkeypatch.setitem(COMMANDS, "demo", Command("a stand-in", lost))
    assert main(["demo"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("peano-bayes demo: failed:") and "Traceback" not in err


def test_a_negative_seed_is_refused_by_every_command_that_takes_one(capsys):
    for argv in (["fit", "TP", "--out", "x"], ["metrics", "x"], ["discover", "TP", "--out", "x"], ["run"]):
        assert main([*argv, "--seed", "-1"]) == 2
        assert "argument --seed: expected a whole number >= 0, got '-1'" in capsys.readouterr().err


def test_fit_does_not_replace_a_finished_result_unless_asked(own_muscle, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(pipeline, "infer", _fake_infer(True))
    finished = tmp_path / "out" / "VM_first"
    finished.mkdir(parents=True)
    (finished / "summary.json").write_text("{}")
    argv = ["fit", str(own_muscle), "--out", str(tmp_path / "out"), "--prior", "TPC"]
    assert main(argv) == 2
    assert "holds a finished result; pass --force" in capsys.readouterr().err
    assert main([*argv, "--force"]) == 0
    assert main([*argv, "--label", "fresh", "--resume"]) == 0
    assert "nothing saved in" in capsys.readouterr().err


def test_a_positional_argument_a_list_option_took_is_explained(capsys):
    """argparse gives every word after a list option to it, so ``--base a,b TP`` leaves DATA missing; the message
    says why and what to do."""
    assert main(["discover", "--base", "hysteresis", "TP", "--out", "o"]) == 2
    err = capsys.readouterr().err
    assert "required: DATA (a list option such as --base takes every word after it" in err
    assert "give the positional arguments first" in err
    assert main(["discover", "TP"]) == 2  # a missing option is not that case
    assert "required: --out\n" in capsys.readouterr().err


def test_output_folders_are_checked_before_any_work(tmp_path, capsys):
    taken = tmp_path / "taken"
    taken.write_text("a file")
    assert main(["discover", "TP", "--out", str(taken)]) == 2
    assert f"--out {taken}: a file; expected a folder" in capsys.readouterr().err
    assert main(["simulate", "--material", "TP", "--out", str(taken / "sim.csv")]) == 2
    assert "--out" in capsys.readouterr().err and taken.read_text() == "a file"
    assert main(["simulate", "--material", "TP", "--out", str(tmp_path / "sim.txt")]) == 2  # not sim.txt.csv
    assert f"give {tmp_path / 'sim.csv'} (or {tmp_path / 'sim.txt'}.csv" in capsys.readouterr().err
    assert main(["simulate", "--material", "TP", "--out", str(tmp_path / "sim.csv.bak")]) == 2
    assert f"give {tmp_path / 'sim.csv'} (or " in capsys.readouterr().err
    assert not list(tmp_path.glob("sim*"))
    (tmp_path / "TP").mkdir()
    assert main(["rank", str(tmp_path / "TP"), str(tmp_path / "TP")]) == 2
    assert "given more than once" in capsys.readouterr().err


def test_a_fan_out_that_fails_before_any_result_leaves_no_folder(tmp_path, monkeypatch, capsys):
    """``run`` and ``fit-many`` stopped before any result (here: a scheduler that cannot be reached, after the
    run log was opened) remove the output folder they created; one that existed before is kept."""
    import peano_bayes.app.batch as batch
    from peano_bayes.errors import PeanoBayesError

    def unreachable(out):
        Path(out).mkdir(parents=True, exist_ok=True)
        batch.RunLog(Path(out) / "run.log", None)("started")
        raise PeanoBayesError("Timed out trying to connect to tcp://127.0.0.1:1")

    monkeypatch.setattr(batch, "run_bundled", lambda out, **kw: unreachable(out))
    monkeypatch.setattr(batch, "fit_many", lambda paths, out, **kw: unreachable(out))
    data = str(bundled.dataset_path("TP"))
    for argv in (["run", "--materials", "TP"], ["fit-many", data]):
        out = tmp_path / argv[0]
        assert main([*argv, "--out", str(out)]) == 1
        assert "failed: Timed out trying to connect" in capsys.readouterr().err and not out.exists(), argv
        out.mkdir()  # a folder the user already had stays, run log and all
        assert main([*argv, "--out", str(out)]) == 1
        assert (out / "run.log").exists()


def test_the_main_job_runs_discovery_first_unless_told_not_to(tmp_path, monkeypatch):
    """``run`` samples the model discovery chooses for each material by default (``--no-discover``: the configured
    model); ``fit-many``, like ``fit``, only with ``--discover``."""
    import peano_bayes.app.batch as batch

    seen = []
    monkeypatch.setattr(batch, "run_bundled", lambda out, **kw: seen.append(("run", kw["discover"])) or [])
    monkeypatch.setattr(batch, "fit_many", lambda paths, out, **kw: seen.append(("many", kw["discover"])) or [])
    out = str(tmp_path / "r")
    assert main(["run", "--out", out, "--materials", "TP"]) == 0
    assert main(["run", "--out", out, "--materials", "TP", "--no-discover"]) == 0
    assert main(["run", "--out", out, "--materials", "TP", "--discover"]) == 0  # the default, said out loud
    data = str(bundled.dataset_path("TP"))
    assert main(["fit-many", data, "--out", out]) == 0
    assert main(["fit-many", data, "--out", out, "--discover"]) == 0
    assert seen == [("run", True), ("run", False), ("run", True), ("many", False), ("many", True)]


def test_bad_invocations_are_refused_up_front_with_what_was_expected(tmp_path, capsys, monkeypatch):
    """A mistyped material code, a code given twice, --resume with --force: exit 2, a message that names the
    input and what was expected, under --json also as the one object on stdout, and nothing written."""
    monkeypatch.chdir(tmp_path)
    assert main(["check", "XX", "--json"]) == 2
    captured = capsys.readouterr()
    assert "XX: neither a bundled material code nor a dataset file" in captured.err and "TP P PR" in captured.err
    assert json.loads(captured.out)["exit_status"] == 2
    out = tmp_path / "r"
    assert main(["run", "--out", str(out), "--materials", "P", "p"]) == 2  # codes are case-blind
    assert "--materials: P given more than once" in capsys.readouterr().err and not out.exists()
    assert main(["fit", "TP", "--out", str(out), "--resume", "--force"]) == 2
    assert "not allowed with argument" in capsys.readouterr().err
    assert not out.exists()


def test_a_command_line_that_cannot_be_parsed_answers_under_json_with_the_commands_own_usage(tmp_path, capsys):
    """argparse's refusals exit 2 like any bad input: under --json stdout holds the one error object; an option
    the command does not take is reported with that command's usage, not the top level's; an option every
    command takes, put before the command's name, is told where it goes."""
    assert main(["demo", "--json", "--pressures-kpa", "abc"]) == 2
    captured = capsys.readouterr()
    assert json.loads(captured.out) == {
        "error": "error: argument --pressures-kpa: invalid float value: 'abc'",
        "exit_status": 2,
    }
    assert captured.err.startswith("usage: peano-bayes demo") and "Traceback" not in captured.err
    out = tmp_path / "r"
    assert main(["run", "--out", str(out), "--prior", "p.toml"]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.startswith("usage: peano-bayes run")
    assert "peano-bayes run: error: unrecognized arguments: --prior p.toml" in captured.err and not out.exists()
    assert main(["--json", "check", "TP"]) == 2
    captured = capsys.readouterr()
    assert "--json goes after the command's name: peano-bayes check --json" in captured.err
    assert json.loads(captured.out)["exit_status"] == 2
    assert main([]) == 2 and "required: COMMAND" in capsys.readouterr().err


def test_an_out_that_is_a_file_or_empty_is_refused_by_the_fitting_commands(tmp_path, capsys):
    taken = tmp_path / "taken"
    taken.write_text("a file")
    for argv in (["fit", "TP"], ["fit-many", "TP", "FC"], ["run"]):
        assert main([*argv, "--out", str(taken)]) == 2, argv
        assert f"--out {taken}: a file; expected a folder (existing or new)" in capsys.readouterr().err, argv
    assert main(["fit", "TP", "--out", ""]) == 2
    assert "--out: an empty path; expected a folder" in capsys.readouterr().err
    assert taken.read_text() == "a file"


def test_the_step_limit_help_says_how_each_command_continues_a_run(capsys):
    """``fit`` continues with --resume; ``run`` and ``fit-many`` have no such option: they resume by themselves."""
    helps = {}
    for name in ("fit", "run", "fit-many"):
        with pytest.raises(SystemExit):
            main([name, "--help"])
        helps[name] = " ".join(capsys.readouterr().out.split())
    assert "so --resume with a larger limit continues it" in helps["fit"]
    for name in ("run", "fit-many"):
        assert "so the same command again with a larger limit continues it" in helps[name]
        assert "--resume" not in helps[name] and "<label>" not in helps[name]


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs a /proc file system, where no file can be made")
def test_an_out_folder_where_nothing_can_be_created_is_refused_before_the_work(capsys):
    """Permission bits say yes to root everywhere; the check creates a file to be sure, so a folder under /proc
    is refused (exit 2) before the rig simulates anything."""
    assert main(["simulate", "--material", "TP", "--out", "/proc/peano_bayes_out/TP.csv"]) == 2
    captured = capsys.readouterr()
    assert "/proc is not a folder this user can write into" in captured.err and "simulated" not in captured.out
