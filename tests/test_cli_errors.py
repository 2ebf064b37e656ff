"""Every CLI error is one line on stderr with exit status 2, found before anything is
written; ``--out`` never mixes two runs."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from train import cli_eval, cli_sweep, cli_train, demo
from train.config import train_config_from_mapping
from train.hyperparams import check_hyperparams
from train.outdir import OutDirError, check_out_dir, clear_previous_run

ROOT = Path(__file__).resolve().parents[1]
SMOKE = {
    "algo": "PPO",
    "env": {"n_agents": 3, "max_steps": 30, "n_neighbors": 2},
    "n_swarms": 2,
    "total_timesteps": 256,
    "net_arch": [16, 16],
    "hyperparams": {"n_steps": 64, "batch_size": 64, "n_epochs": 1},
}
EVAL_QUICK = ["--policies", "zero", "--episodes", "1", "--max-steps", "5", "--no-gif"]
EVAL_QUICK += ["--no-plots", "--no-progress", "--set", "n_agents=3"]


@pytest.fixture
def files(tmp_path: Path) -> dict[str, Path]:
    (tmp_path / "bad.yaml").write_text("algo: PPO\nn_swarms: [2\n")
    (tmp_path / "smoke.yaml").write_text(yaml.safe_dump(SMOKE))
    (tmp_path / "a_file").write_text("x")
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "notes.txt").write_text("x")
    return {p.stem: p for p in tmp_path.iterdir()}


def status(main, argv: list[str]) -> int:
    """The exit status of ``main(argv)``, whether it returns it or argparse exits."""
    try:
        return main(argv)
    except SystemExit as exit_:
        return int(exit_.code or 0)


def one_error_line(capsys, prog: str) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"{prog}: error: "), err
    return err


TRAIN_CASES = [
    (["--config", "{bad}"], "invalid YAML at line 3, column 1"),
    (["--config", "{tmp}/missing.yaml"], "train config not found"),
    (["--config", "{smoke}", "--out", "{a_file}"], "is a file; give a folder"),
    (["--config", "{smoke}", "--out", "{a_file}/sub"], "which is a file"),
    (["--config", "{smoke}", "--out", "{full}"], "already holds files"),
    (["--config", "{smoke}", "hyperparams.learning_rate=-1"], "learning_rate must be a number"),
    (["--config", "{smoke}", "hyperparams.n_steps=0"], "n_steps must be an integer >= 1"),
    (["--config", "{smoke}", "hyperparams.gamma=1.5"], "gamma must be a number in (0, 1]"),
    (["--config", "{smoke}", "hyperparams.batch_size=1"], "batch_size must be >= 2"),
    (["--config", "{smoke}", "seed=-1"], "seed must be an integer >= 0"),
    (["--config", "{smoke}", "seed=[1"], "invalid YAML"),
    (["--config", "{smoke}", "novalue"], "must look like key=value"),
    (["--config", "{smoke}", "device=nonsense"], "device must be a torch device name"),
    (["--config", "{smoke}", "env_config={bad}"], "invalid YAML"),
    (["--config", "{smoke}", "--num-cpus", "x"], "invalid int value"),
    (["--config", "{smoke}", "--engine", "nope"], "invalid choice"),
    ([], "give --config FILE"),
    (["--resume", "{tmp}/nothing"], "no train_config.yaml"),
]


@pytest.mark.parametrize(("argv", "fragment"), TRAIN_CASES)
def test_swarm_train_errors_are_one_line_and_write_nothing(
    files, tmp_path, capsys, monkeypatch, argv, fragment
):
    monkeypatch.chdir(tmp_path)  # the default --out (runs/<name>) lands here
    names = {k: str(v) for k, v in files.items()} | {"tmp": str(tmp_path)}
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    assert status(cli_train.main, [a.format(**names) for a in argv]) == 2
    assert fragment in one_error_line(capsys, "swarm-train")
    assert sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*")) == before


EVAL_CASES = [
    (["--seed", "-1"], "--seed must be an integer in [0, 4294967295]"),
    (["--config", "{bad}"], "invalid YAML at line 3, column 1"),
    (["--config", "{tmp}/missing.yaml"], "config file not found"),
    (["--out", "{a_file}"], "is a file"),
    (["--out", "{full}"], "already holds files"),
    (["--set", "physics=[1"], "invalid YAML"),
    (["--device", "cuda:7"], "--device"),
    (["--gif-size", "10"], "--gif-size must be in [32, 4096]"),
]


@pytest.mark.parametrize(("argv", "fragment"), EVAL_CASES)
def test_swarm_eval_errors_are_one_line_and_write_nothing(files, tmp_path, capsys, argv, fragment):
    names = {k: str(v) for k, v in files.items()} | {"tmp": str(tmp_path)}
    argv = [a.format(**names) for a in argv]
    out = [] if "--out" in argv else ["--out", str(tmp_path / "o")]
    assert cli_eval.main([*EVAL_QUICK, *out, *argv]) == 2
    assert fragment in one_error_line(capsys, "swarm-eval")
    assert not (tmp_path / "o").exists()
    assert [p.name for p in (tmp_path / "full").iterdir()] == ["notes.txt"]


def test_argparse_errors_are_one_line_with_exit_2(capsys):
    assert status(cli_eval.main, ["--episodes", "many"]) == 2
    assert "argument --episodes: invalid int value" in one_error_line(capsys, "swarm-eval")


def test_demo_and_sweep_check_their_output_folder_first(files, capsys):
    assert demo.main(["--config", str(files["smoke"]), "--out", str(files["full"])]) == 2
    assert "already holds files" in one_error_line(capsys, "swarm-demo")
    assert demo.main(["--config", str(files["smoke"]), "--seed", "-5"]) == 2
    assert "--seed must be an integer" in one_error_line(capsys, "swarm-demo")
    argv = ["--config", "quick", "--engine", "local", "--out", str(files["a_file"])]
    assert cli_sweep.main(argv) == 2
    assert "is a file" in one_error_line(capsys, "swarm-sweep")
    assert cli_sweep.main(["--config", str(files["bad"]), "--engine", "local"]) == 2
    assert "invalid YAML" in one_error_line(capsys, "swarm-sweep")


def test_console_script_error_is_one_line(files):
    proc = subprocess.run(
        [sys.executable, "-m", "train.cli_train", "--config", str(files["bad"])],
        cwd=files["bad"].parent,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1
    assert "Traceback" not in proc.stderr and "invalid YAML" in proc.stderr


# --------------------------------------------------------------------------- --overwrite


def test_train_overwrite_clears_the_earlier_run(files, tmp_path, capsys):
    out = tmp_path / "run"
    base = ["--config", str(files["smoke"]), "--out", str(out), "--no-progress"]
    assert cli_train.main(base) == 0
    (out / "best_model.zip").write_text("stale")  # an output the next run does not write
    (out / "results.json").write_text("{}")  # an evaluation of the earlier model
    (out / "notes.txt").write_text("mine")
    capsys.readouterr()
    assert cli_train.main(base) == 2  # refused: the folder holds a run
    assert "--overwrite" in one_error_line(capsys, "swarm-train")
    assert cli_train.main([*base, "--overwrite", "seed=5"]) == 0
    assert "kept 1 other(s): notes.txt" in capsys.readouterr().out
    assert not (out / "best_model.zip").exists() and not (out / "results.json").exists()
    assert (out / "notes.txt").read_text() == "mine"
    assert yaml.safe_load((out / "train_config.yaml").read_text())["seed"] == 5


def test_eval_overwrite_replaces_the_evaluation_only(tmp_path, capsys):
    out = tmp_path / "e"
    out.mkdir()
    for name in ("results.json", "summary.md", "episode0_gone.gif", "model.zip"):
        (out / name).write_text("old")
    assert cli_eval.main([*EVAL_QUICK, "--out", str(out)]) == 2
    capsys.readouterr()
    assert cli_eval.main([*EVAL_QUICK, "--out", str(out), "--overwrite"]) == 0
    assert not (out / "episode0_gone.gif").exists()
    assert (out / "model.zip").read_text() == "old"  # an input, not an evaluation output
    assert list(json.loads((out / "results.json").read_text())["policies"]) == ["zero"]


def test_out_dir_helpers(tmp_path):
    check_out_dir(tmp_path / "new", overwrite=False)  # missing: fine, nothing created
    assert not (tmp_path / "new").exists()
    (tmp_path / "empty").mkdir()
    check_out_dir(tmp_path / "empty", overwrite=False)
    (tmp_path / "empty" / "x").write_text("")
    with pytest.raises(OutDirError, match="already holds files"):
        check_out_dir(tmp_path / "empty", overwrite=False)
    (tmp_path / "run" / "checkpoints").mkdir(parents=True)
    (tmp_path / "run" / "model.zip").write_text("")
    (tmp_path / "run" / "keep.txt").write_text("")
    removed, kept = clear_previous_run(tmp_path / "run", ["model.zip", "checkpoints"])
    assert removed == ["checkpoints", "model.zip"] and kept == ["keep.txt"]


# --------------------------------------------------------------------------- hyperparams


@pytest.mark.parametrize(
    ("algo", "hyper", "fragment"),
    [
        ("PPO", {"learning_rate": 0}, "learning_rate must be a number in (0, inf)"),
        ("PPO", {"learning_rate": "fast"}, "learning_rate must be a number"),
        ("PPO", {"n_epochs": 0}, "n_epochs must be an integer >= 1"),
        ("PPO", {"gae_lambda": 1.1}, "gae_lambda must be a number in [0, 1]"),
        ("PPO", {"clip_range": -0.2}, "clip_range must be a number in (0, inf)"),
        ("PPO", {"target_kl": 0}, "(or null)"),
        ("PPO", {"normalize_advantage": "yes"}, "must be true or false"),
        ("PPO", {"rollout_buffer_class": "x"}, "takes a Python object"),
        ("SAC", {"buffer_size": 0}, "buffer_size must be an integer >= 1"),
        ("SAC", {"tau": 0}, "tau must be a number in (0, 1]"),
        ("SAC", {"train_freq": [4, "episode"]}, "unit 'episode'"),
        ("SAC", {"gradient_steps": 0}, "gradient_steps must be an integer >= 1 or -1"),
        ("SAC", {"ent_coef": "auto_-1"}, "ent_coef must be 'auto'"),
        ("SAC", {"learning_starts": -1}, "learning_starts must be an integer >= 0"),
    ],
)
def test_bad_hyperparameters_name_the_key(algo, hyper, fragment):
    with pytest.raises(ValueError) as info:
        train_config_from_mapping({**SMOKE, "algo": algo, "hyperparams": hyper})
    assert fragment in str(info.value)


def test_hyperparameters_accept_numbers_written_as_yaml_text():
    tc = train_config_from_mapping({**SMOKE, "hyperparams": {"learning_rate": "3e-4"}})
    assert tc.hyperparams["learning_rate"] == 3e-4
    assert check_hyperparams("SAC", {"ent_coef": "auto_0.1", "train_freq": [2, "step"]}, 4) == {
        "ent_coef": "auto_0.1",
        "train_freq": [2, "step"],
    }
    with pytest.raises(ValueError, match="n_steps × env slots must be > 1"):
        check_hyperparams("PPO", {"n_steps": 1}, 1)


# --------------------------------------------------------------------------- --help


def _scripts() -> dict[str, str]:
    import tomllib

    return tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]


@pytest.mark.parametrize("program", sorted(_scripts()))
def test_help_describes_the_tool_and_every_option(program, monkeypatch):
    """Each console script's parser: a whole-sentence description, help on every
    option, and the default named wherever an option has a number as default."""
    import argparse
    import importlib

    module, _, func = _scripts()[program].partition(":")
    parsers: list[argparse.ArgumentParser] = []

    def capture(self, *args, **kwargs):
        parsers.append(self)
        raise SystemExit(0)

    monkeypatch.setattr(argparse.ArgumentParser, "parse_args", capture)
    with pytest.raises(SystemExit):
        getattr(importlib.import_module(module), func)([])
    (parser,) = parsers
    description = (parser.description or "").strip()
    assert description.endswith((".", ")")), f"{program}: description {description!r}"
    for action in parser._actions:
        if isinstance(action, argparse._HelpAction):
            continue
        assert action.help, f"{program} {action.option_strings or action.dest}: no help text"
        numeric = isinstance(action.default, (int, float)) and not isinstance(action.default, bool)
        if numeric and action.option_strings:
            assert "default" in action.help, f"{program} {action.option_strings}: no default"
