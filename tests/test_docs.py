"""The specification lives in the repository: every link of README.md and docs/*.md resolves inside it, and no doc,
help text or source comment sends the reader outside it (docs/spec.md is the contract)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.support import ROOT

DOCS = sorted((ROOT / "docs").glob("*.md"))
PAGES = [ROOT / "README.md", *DOCS]
# [text](target) and ![alt](target); a target ends at whitespace or the closing parenthesis.
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")
HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*#*\s*$")
OUTSIDE = ("ARCHITECTURE.md", "../shared")


def anchors(md: Path) -> set[str]:
    """GitHub's heading anchors: lower case, punctuation dropped (not - or _), spaces to hyphens, repeats -1, -2."""
    seen: dict[str, int] = {}
    out = set()
    in_code = False
    for line in md.read_text().splitlines():
        if line.startswith("```"):
            in_code = not in_code
        m = None if in_code else HEADING.match(line)
        if not m:
            continue
        slug = re.sub(r"[^\w\- ]", "", m.group(2).lower()).replace(" ", "-")
        n = seen.get(slug, 0)
        seen[slug] = n + 1
        out.add(slug if n == 0 else f"{slug}-{n}")
    return out


def links(md: Path) -> list[str]:
    text = re.sub(r"```.*?```", "", md.read_text(), flags=re.S)  # code blocks hold code, not links
    return LINK.findall(text)


def test_the_specification_exists():
    names = {p.name for p in DOCS}
    assert {"spec.md", "dsl.md", "formats.md", "scenic.md", "cli.md"} <= names
    # The index names every page of the specification.
    index = (ROOT / "docs" / "spec.md").read_text()
    assert all(f"]({name})" in index for name in names - {"spec.md"}), names


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_every_relative_link_resolves_inside_the_repository(page):
    bad = []
    for target in links(page):
        if re.match(r"[a-z][a-z0-9+.-]*:", target):  # http:, https:, mailto:
            continue
        path, _, anchor = target.partition("#")
        file = (page.parent / path).resolve() if path else page
        if ROOT.resolve() not in (file, *file.parents):
            bad.append(f"{target}: outside the repository")
        elif not file.exists():
            bad.append(f"{target}: no such file")
        elif anchor and file.suffix == ".md" and anchor not in anchors(file):
            bad.append(f"{target}: no heading #{anchor} in {file.name}")
    assert not bad, f"{page.name}: " + "; ".join(bad)


@pytest.mark.parametrize("page", DOCS, ids=lambda p: p.name)
def test_the_specification_is_self_contained(page):
    """No link out of the repository at all: a clone is the whole contract."""
    text = page.read_text()
    assert not re.search(r"https?://", text), page.name
    assert not any(s in text for s in OUTSIDE), page.name


def test_no_page_help_or_source_points_outside_the_repository():
    from pipeline.cli import VERBS, build_parser

    texts = {p.name: p.read_text() for p in PAGES}
    for verb in VERBS:
        texts[f"r2s {verb} --help"] = build_parser(verb).format_help()
    for folder in ("synth", "extractors", "pipeline", "configs", "data"):
        for f in (ROOT / folder).rglob("*"):
            if f.is_file() and f.suffix in (".py", ".toml", "") and "__pycache__" not in f.parts:
                texts[str(f.relative_to(ROOT))] = f.read_text(errors="replace")
    bad = [name for name, text in texts.items() if "ARCHITECTURE.md" in text]
    assert not bad, bad
    # Whatever names a page of docs/ names one that exists.
    missing = sorted({(name, m) for name, text in texts.items() for m in re.findall(r"docs/[\w-]+\.md", text)
                      if not (ROOT / m).exists()})
    assert not missing, missing


def python_blocks(md: Path) -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", md.read_text(), flags=re.S | re.M)


# A ```sh block of the README runs in the tests unless this comment stands on the line before it, with a reason.
SKIP = re.compile(r"^<!-- not run by tests/test_docs\.py: (.+?) -->$")
ACTIVATE = ". .venv/bin/activate"


def sh_blocks(md: Path) -> list[tuple[str, str | None]]:
    """(block, reason it is not run, or None) for every ```sh block, in order."""
    lines = md.read_text().splitlines()
    out = []
    for i, line in enumerate(lines):
        if line == "```sh":
            end = lines.index("```", i + 1)
            marker = SKIP.match(lines[i - 1]) if i else None
            out.append(("\n".join(lines[i + 1:end]) + "\n", marker.group(1) if marker else None))
    return out


def section(md: Path, heading: str) -> str:
    text = md.read_text()
    start = text.index(f"\n{heading}\n")
    level = heading.split()[0]
    rest = re.search(rf"^#{{1,{len(level)}}} ", text[start + len(heading) + 2:], flags=re.M)
    return text[start:start + len(heading) + 2 + (rest.start() if rest else len(text))]


def as_a_user(tmp_path: Path, script: str, stdin: str | None = None):
    """Runs `script` in a fresh bash, after the README's own setup line (the venv's activation), from a directory
    laid out like the repository's root: the shipped data, configs and the venv linked in, nothing else, so
    whatever the commands write lands in tmp_path and never in the repository."""
    import os
    import subprocess
    import sys

    venv = Path(sys.prefix)
    if not (venv / "bin" / "activate").exists() or not (venv / "bin" / "r2s").exists():
        pytest.skip(f"the tests do not run in a venv with r2s installed ({venv}): `make test` runs them in .venv")
    for name in ("data", "configs"):
        (tmp_path / name).symlink_to(ROOT / name)
    (tmp_path / ".venv").symlink_to(venv)
    # A new shell: the venv's bin off PATH, as before activation.
    path = os.pathsep.join(d for d in os.environ.get("PATH", "").split(os.pathsep)
                           if d and Path(d).resolve() != (venv / "bin").resolve())
    env = {k: v for k, v in os.environ.items() if k not in ("VIRTUAL_ENV", "PYTHONPATH")} | {"PATH": path}
    before = set(ROOT.iterdir())
    proc = subprocess.run(["bash", "--noprofile", "--norc", "-c", f"set -eo pipefail\n{ACTIVATE}\n{script}"],
                          cwd=tmp_path, env=env, input=stdin, capture_output=True, text=True, timeout=600)
    assert set(ROOT.iterdir()) == before, sorted(map(str, set(ROOT.iterdir()) ^ before))
    return proc


README_SH = sh_blocks(ROOT / "README.md")


def test_the_readme_says_where_to_activate_the_venv():
    """The setup line is in the README (after `make demo`), and every block it does not run says why."""
    blocks = sh_blocks(ROOT / "README.md")
    assert any(block.strip().startswith(ACTIVATE) for block, _ in blocks)
    assert section(ROOT / "README.md", "### Examples").count(ACTIVATE) >= 1
    assert all(reason is None or reason.strip() for _, reason in blocks)
    # The Examples are run, never skipped.
    examples = re.findall(r"^```sh\n(.*?)^```", section(ROOT / "README.md", "### Examples"), flags=re.S | re.M)
    assert examples and all((b, None) in blocks for b in examples)


@pytest.mark.parametrize("k", [k for k, (block, reason) in enumerate(README_SH)
                               if reason is None and not block.strip().startswith(ACTIVATE)])
def test_readme_shell_block_runs_as_written(k, tmp_path):
    """Each ```sh block of the README without a marker, as a user types it into a new shell after the README's
    setup line."""
    block = README_SH[k][0]
    proc = as_a_user(tmp_path, block)
    assert proc.returncode == 0, f"README sh block {k + 1}:\n{block}\n{proc.stderr[-2000:]}"
    assert_writes_only_under_out(tmp_path)


def assert_writes_only_under_out(tmp_path: Path) -> None:
    """The examples write under out/ (git ignores it), never beside the data in a user's clone."""
    written = sorted(p.name for p in tmp_path.iterdir() if p.name not in ("data", "configs", ".venv", "out"))
    assert not written, f"written outside out/: {written}"


def test_the_readme_has_a_python_quick_start():
    blocks = python_blocks(ROOT / "README.md")
    assert any("from synth import" in b for b in blocks) and any("run_frames" in b for b in blocks)


@pytest.mark.parametrize("page,k", [(page, k) for page in ("README.md", "docs/api.md")
                                    for k in range(len(python_blocks(ROOT / page)))])
def test_python_block_runs_as_written(page, k, tmp_path):
    """Each ```python block of the README and of docs/api.md, alone, in the `python` of a new shell after the
    README's setup line, from a directory that has the shipped data where the repository's root has it (the README
    says: from the repository's root)."""
    block = python_blocks(ROOT / page)[k]
    proc = as_a_user(tmp_path, "python -", stdin=block)
    assert proc.returncode == 0, f"{page} python block {k + 1}:\n{block}\n{proc.stderr[-2000:]}"
    assert_writes_only_under_out(tmp_path)


def test_the_layout_map_names_every_room_and_module():
    """docs/layout.md is where a newcomer finds the room for a change (the README links it): it links every package
    of the code and names every module of synth/, storage/, frames/, extractors/ and pipeline/'s rooms, so a move or a new module
    that forgets the map fails here."""
    layout = ROOT / "docs" / "layout.md"
    text = layout.read_text()
    linked = {(layout.parent / t).resolve() for t in links(layout)}
    unlinked, unnamed = [], []
    for folder in ("synth", "storage", "frames", "extractors", "pipeline"):
        for init in sorted((ROOT / folder).rglob("__init__.py")):
            if init.parent.resolve() not in linked:
                unlinked.append(str(init.parent.relative_to(ROOT)))
    modules = [f for folder in ("synth", "storage", "frames", "extractors", "pipeline") for f in (ROOT / folder).rglob("*.py")]
    for f in sorted(modules):
        if f.name not in ("__init__.py", "__main__.py") and f"`{f.name}`" not in text:
            unnamed.append(str(f.relative_to(ROOT)))
    assert not unlinked and not unnamed, (unlinked, unnamed)
    assert "](docs/layout.md)" in (ROOT / "README.md").read_text()


def test_the_tests_mirror_the_code():
    """Every folder of tests/ (but data/ and support/) is a package of the code, and no test imports conftest or
    another test module (helpers are in tests/support), so a test is where docs/layout.md says it is."""
    tests = ROOT / "tests"
    folders = [d for d in tests.rglob("*") if d.is_dir() and "__pycache__" not in d.parts
               and not {"data", "support"} & set(d.relative_to(tests).parts)]
    assert folders, "tests/ has no subfolders"
    strays = [str(d.relative_to(tests)) for d in folders if not (ROOT / d.relative_to(tests) / "__init__.py").exists()]
    assert not strays, strays
    importers = [str(f.relative_to(ROOT)) for f in tests.rglob("*.py")
                 if re.search(r"^\s*(from conftest import|import conftest|from tests\.(?!support\b)|import tests\.(?!support\b))",
                              f.read_text(), flags=re.M)]
    assert not importers, importers
