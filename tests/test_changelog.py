"""CHANGELOG.md's newest version is the package's: the one pyproject.toml declares, the installed
metadata carries and `vemdem --version` prints."""

import re
import tomllib
from importlib.metadata import version
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def changelog_versions() -> list[str]:
    """The versions of CHANGELOG.md's `## [X.Y.Z]` headings, newest (first) first."""
    text = (ROOT / "CHANGELOG.md").read_text()
    return re.findall(r"^## \[(\d+\.\d+\.\d+[^\]]*)\]", text, flags=re.MULTILINE)


def test_the_newest_changelog_version_is_the_package_version(cli, capsys):
    newest = changelog_versions()[0]
    declared = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
    assert newest == declared == version("vemdem")
    with pytest.raises(SystemExit) as stop:
        cli("--version")
    assert stop.value.code == 0 and capsys.readouterr().out.strip() == f"vemdem {newest}"


def test_each_version_is_listed_once_newest_first():
    versions = changelog_versions()
    numbers = [tuple(int(p) for p in re.match(r"(\d+)\.(\d+)\.(\d+)", v).groups()) for v in versions]
    assert versions and len(set(versions)) == len(versions) and numbers == sorted(numbers, reverse=True)
