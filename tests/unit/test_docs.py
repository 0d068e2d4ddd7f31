"""The docs can't drift from the code: the generated reference pages and the config schema equal
a fresh generation (``python -m controller.docs``), every relative link of README.md resolves,
the lab page's copy of the README's lab block is the block, the troubleshooting page explains
every failure ``Reason``, and the code's citations of the architecture page name sections it
has."""

from __future__ import annotations

import re

import pytest

from controller.docs import GENERATED, REGENERATE, stale
from controller.events import Reason
from tests.support.config import ROOT

LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")


def test_the_generated_pages_and_schema_are_current():
    old = stale(ROOT)
    assert not old, f"stale: {', '.join(old)}: run `{REGENERATE}` and commit the result"


def test_every_generated_file_is_in_the_repository():
    for path in GENERATED:
        assert (ROOT / path).is_file(), f"{path} missing: run `{REGENERATE}`"


def _relative_links(path) -> list[str]:
    text = path.read_text(encoding="utf-8")
    text = re.sub(r"```.*?```", "", text, flags=re.S)  # code blocks hold no links
    return [
        t for t in LINK.findall(text) if not re.match(r"^[a-z][a-z0-9+.-]*:", t) and t[0] != "#"
    ]


@pytest.mark.parametrize("name", ["README.md", "CONTRIBUTING.md", "CHANGELOG.md"])
def test_every_relative_link_resolves(name):
    path = ROOT / name
    links = _relative_links(path)
    if name == "README.md":
        assert len(links) >= 10 and any(t.startswith("docs/") for t in links)
    missing = [t for t in links if not (path.parent / t.split("#", 1)[0]).exists()]
    assert not missing, f"{name} links to missing files: {missing}"


def _fenced_after(text: str, mark: str) -> str:
    after = text[text.index(mark) :]
    return after.split("```", 2)[1]


def test_the_lab_page_shows_the_readme_lab_block_as_it_is():
    """The README's block is the one tests/integration/test_lab_up.py runs; the lab page's copy
    must not drift from it."""
    readme = _fenced_after((ROOT / "README.md").read_text(encoding="utf-8"), "<!-- lab-quickstart")
    page = (ROOT / "docs" / "lab" / "index.md").read_text(encoding="utf-8")
    assert _fenced_after(page, "lab quick start, copied") == readme


def test_the_troubleshooting_page_explains_every_failure_reason():
    text = (ROOT / "docs" / "lab" / "troubleshooting.md").read_text(encoding="utf-8")
    headings = set(re.findall(r"^#+ `([a-z_]+)`", text, flags=re.M))
    missing = [r.value for r in Reason if r.value not in headings]
    assert not missing, f"docs/lab/troubleshooting.md: no section for {missing}"


def test_the_codes_architecture_citations_name_sections_of_the_page():
    page = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    sections = set(re.findall(r"^#+ (.+)$", page, flags=re.M))
    cited = []
    for folder in ("controller", "drivers", "sim_backend", "tests"):
        for path in (ROOT / folder).rglob("*.py"):
            text = path.read_text(encoding="utf-8")
            if path.name == "test_docs.py":
                continue
            for m in re.finditer(r"docs/architecture\.md, \"([^\"\n]+)\"", text):
                cited.append((path.relative_to(ROOT), m.group(1)))
            old = re.search(r"ARCHITECTURE(\.md)?,? \"", text)  # the design document's name
            assert not old, f"{path}: cite docs/architecture.md instead"
    assert cited
    for where, section in cited:
        assert section in sections, f"{where} cites {section!r}, not a section of the page"


def test_the_results_pages_are_current_with_the_committed_rows():
    """Every generated block of docs/results/ is what bench/pages.py writes from its row in
    bench/rows/ (a row re-recorded without the pages regenerated fails here), and every block
    has its row (no page keeps numbers nobody can trace)."""
    from bench import pages

    blocks = 0
    for page in sorted(pages.PAGES.glob("*.md")):
        text = page.read_text()
        for m in pages.BLOCK.finditer(text):
            blocks += 1
            assert (pages.ROWS / f"{m.group('name')}.json").is_file(), (page.name, m["name"])
        assert pages.rewrite(text) == text, f"{page.name}: run python bench/pages.py"
    assert blocks >= 4


def test_a_results_block_names_its_row_and_flags_a_missed_goal(tmp_path, monkeypatch):
    from bench import pages

    row = {
        "bench": "approach", "command": "python bench/approach.py", "commit": "abc", "dirty": False,
        "date": "2026-11-28", "machine": {"cores": 2, "python": "3.11", "loop_1e7_s": 0.6},
        "load_before": [0.4], "load_after": [0.5],
        "result": {"sizes": {"20": {
            "planner": {"median_ms": 0.8}, "filter_warm": {"median_ms": 2.5},
            "filter_warm_half_differential": {"median_ms": 3.0},
            "filter_cold_rebuild": {"median_ms": 5.0}, "speedup_median": 2.0}},
            "goal": "filter < 2 ms median at 20 robots", "goal_met": False},
    }  # fmt: skip
    (tmp_path / "approach.json").write_text(__import__("json").dumps(row))
    monkeypatch.setattr(pages, "ROWS", tmp_path)
    out = pages.rewrite("x\n<!-- rows: approach -->\nold 0.52 ms\n<!-- /rows -->\ny\n")
    assert "old 0.52" not in out and "| 20 | 0.80 ms | 2.50 ms |" in out
    assert "**not met**" in out and "`bench/rows/approach.json`" in out and "commit `abc`" in out
    gone = pages.rewrite("<!-- rows: sim -->\n1 2 3\n<!-- /rows -->\n")
    assert "No row yet" in gone and "1 2 3" not in gone
