"""The documentation site builds: `mkdocs build --strict` with every page in the nav, every link
and anchor resolved and every API page rendered from the docstrings without a warning
(mkdocs.yml's `validation` turns omitted pages and broken links into warnings, and --strict turns
warnings into a failed build)."""

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_the_site_builds_in_strict_mode_without_warnings(tmp_path):
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}  # Material's banner, not a build warning
    run = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file", str(ROOT / "mkdocs.yml"),
         "--site-dir", str(tmp_path / "site")],
        cwd=ROOT, capture_output=True, text=True, env=env, timeout=600,
    )  # fmt: skip
    log = run.stdout + run.stderr
    warnings = [line for line in log.splitlines() if line.startswith(("WARNING", "ERROR"))]
    problems = "\n".join(warnings or [log[-3000:]])
    assert run.returncode == 0 and not warnings, f"mkdocs build --strict failed:\n{problems}"
    for page in ("index.html", "getting-started/index.html", "reference/config/index.html", "api/solver/index.html"):
        assert (tmp_path / "site" / page).is_file(), page
    # the API pages hold the rendered docstrings, not just their headings
    assert "make_integrator" in (tmp_path / "site" / "api" / "solver" / "index.html").read_text()


def test_every_markdown_page_is_in_the_nav():
    """Said by the build too (validation.omitted_files); here it names the page in one line."""
    config = (ROOT / "mkdocs.yml").read_text()
    docs = ROOT / "docs"
    pages = sorted(p.relative_to(docs).as_posix() for p in docs.rglob("*.md"))
    pages = [p for p in pages if not p.startswith("data/")]  # files behind the figures, not pages
    missing = [p for p in pages if f" {p}" not in config and f"- {p}" not in config]
    assert not missing, f"pages missing from mkdocs.yml's nav: {missing}"
