"""Trustworthy runs (docs/errors.md): a used --out is never mixed with a new run, refusals leave nothing
behind, summaries are strict JSON, and mistakes about files are one line with exit status 2."""

import json

import pytest

from vemdem.io.results import write_json
from test_cli import GOOD, write


def test_a_used_folder_is_refused_without_resume_or_overwrite(tmp_path, cli):
    job = write(tmp_path, GOOD)
    assert cli("run", job, "--out", tmp_path / "out", "--quiet")[0] == 0
    code, _, err = cli("run", job, "--out", tmp_path / "out", "--quiet")
    assert code == 2 and "holds the results of another run" in err and "--overwrite" in err
    assert len(err.strip().splitlines()) == 1


def test_overwrite_removes_the_earlier_results_and_only_them(tmp_path, cli):
    out = tmp_path / "out"
    (out / "grains").mkdir(parents=True)
    (out / "grains" / "grains_0099.vtu").write_text("old frame")
    (out / "pile.png").write_text("old plot")
    (out / "notes.txt").write_text("the user's own file")
    code, _, _ = cli("run", write(tmp_path, GOOD), "--out", out, "--overwrite", "--quiet")
    assert code == 0
    assert not (out / "grains").exists() and not (out / "pile.png").exists()
    assert (out / "notes.txt").read_text() == "the user's own file"
    assert (out / "summary.json").is_file()


def test_resume_and_overwrite_exclude_each_other(tmp_path, cli):
    with pytest.raises(SystemExit):
        cli("run", write(tmp_path, GOOD), "--out", tmp_path / "o", "--resume", "--overwrite")


def test_a_refused_run_leaves_no_folder(tmp_path, cli):
    code, _, err = cli("run", write(tmp_path, GOOD.replace("steps = 3", "steps = 0")), "--out", tmp_path / "new")
    assert code == 2 and "loading.steps" in err
    assert not (tmp_path / "new").exists()


def test_out_that_is_a_file(tmp_path, cli):
    (tmp_path / "taken").write_text("x")
    code, _, err = cli("run", write(tmp_path, GOOD), "--out", tmp_path / "taken")
    assert code == 2 and "is a file" in err and "Traceback" not in err


@pytest.mark.parametrize("content", [b"\xff\xfe\x00binary\x00", "scenario = \"scene\"\n".encode("utf-16")])
def test_a_config_that_is_not_utf8_text(tmp_path, cli, content):
    path = tmp_path / "job.toml"
    path.write_bytes(content)
    code, _, err = cli("run", path, "--out", tmp_path / "out")
    assert code == 2 and str(path) in err and len(err.strip().splitlines()) == 1


def test_version(cli, capsys):
    with pytest.raises(SystemExit) as stop:
        cli("--version")
    assert stop.value.code == 0 and "vemdem" in capsys.readouterr().out


def test_summaries_are_strict_json(tmp_path):
    """A NaN becomes null (strict JSON readers reject a bare NaN)."""
    write_json(tmp_path / "s.json", {"angle_of_repose_deg": float("nan"), "nested": [1.0, float("inf")]})
    text = (tmp_path / "s.json").read_text()
    assert "NaN" not in text and "Infinity" not in text
    assert json.loads(text) == {"angle_of_repose_deg": None, "nested": [1.0, None]}
