"""The documentation site builds with ``mkdocs build --strict``, and every relative link in the docs resolves."""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: A relative Markdown link or image: ](target) with no scheme and no in-page anchor only.
LINK = re.compile(r"\]\((?!https?:|mailto:|#)([^)\s]+)\)")


def _missing_links(page: Path) -> list[str]:
    targets = (m.split("#")[0] for m in LINK.findall(page.read_text()))
    return [t for t in targets if t and not (page.parent / t).exists()]


@pytest.mark.parametrize("page", sorted(p.relative_to(ROOT).as_posix() for p in (ROOT / "docs").rglob("*.md")
                                        if "results" not in p.relative_to(ROOT / "docs").parts))
def test_the_docs_links_resolve(page: str) -> None:
    assert not _missing_links(ROOT / page), f"{page} links to missing files: {_missing_links(ROOT / page)}"


def test_the_readme_links_resolve() -> None:
    assert not _missing_links(ROOT / "README.md"), f"README.md links to missing files: {_missing_links(ROOT / 'README.md')}"


#: What mkdocs.yml needs: mkdocs, its material theme and mkdocstrings' Python handler (the ``docs`` extra).
SITE_TOOLS = ("mkdocs", "material", "mkdocstrings", "mkdocstrings_handlers")


@pytest.mark.skipif(any(importlib.util.find_spec(m) is None for m in SITE_TOOLS),
                    reason="the docs extra (mkdocs, mkdocs-material, mkdocstrings[python]) is not installed: "
                    "pip install torch==2.13.0 -e '.[docs]'")
@pytest.mark.slow
def test_the_site_builds_strictly(tmp_path: Path) -> None:
    """A broken link, a missing page in the nav or an API name that no longer exists fails the build."""
    out = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
                         cwd=ROOT, capture_output=True, text=True, timeout=300, env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})
    assert out.returncode == 0, out.stderr[-3000:]
    assert (tmp_path / "site" / "commands" / "collect" / "index.html").exists()
    assert "load_model" in (tmp_path / "site" / "api" / "index.html").read_text()


def test_the_readme_is_a_front_page() -> None:
    """Short, with the two commands for a fresh machine exactly as .ci/run runs the second."""
    readme = (ROOT / "README.md").read_text()
    assert len(readme.splitlines()) <= 250, "the README is the front page; the reference belongs in docs/"
    assert "pip install torch==2.13.0 -e '.[dev]' && piga-demo --out demo\n" in readme
    ci = (ROOT / ".ci" / "run").read_text().strip().splitlines()[-1]
    assert ci == "pip install torch==2.13.0 -e '.[dev,ray]' && python -m pytest" and ci + "\n" in readme
    for word in ("../shared", "/work/", "GUIDE.md"):
        assert word not in readme, f"the README names {word!r}"
    assert not re.search(r"\b(issue|session) \d", readme, re.IGNORECASE), "the README is no development history"
