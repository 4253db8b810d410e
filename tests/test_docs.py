"""The documentation's shape: measured numbers live in the generated experiment pages, docs/history.md
and docs/benchmarks.md, so a reference page says how to run a thing and links to what it measured;
every relative link in the docs reaches an existing file and heading."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
# The pages that hold measurements with their dates: the generated results (docs/results.md and the
# studies/ and docs/archive/ trees, not matched by docs/*.md), superseded protocols, benchmarks, and the
# protocol's version history and the migration notes, which date what changed.
DATED_PAGES = {"results.md", "history.md", "benchmarks.md", "protocol.md", "migration.md"}
REFERENCE_PAGES = sorted(p for p in DOCS.glob("*.md") if p.name not in DATED_PAGES)
LINKED_PAGES = sorted([ROOT / "README.md", *DOCS.rglob("*.md"), *(ROOT / "studies").rglob("*.md")])

DATE = re.compile(r"\b20\d\d-\d\d-\d\d\b")
HEADING = re.compile(r"^#{1,6}\s+(.*)")
LINK = re.compile(r"\]\(([^)\s]+)\)")


def hand_written_measurements(text: str) -> list[str]:
    """`line N: ...` for each heading that says "Measured" and each line that holds a date (20YY-MM-DD)."""
    found = []
    for number, line in enumerate(text.splitlines(), start=1):
        heading = HEADING.match(line)
        if (heading and "Measured" in heading.group(1)) or DATE.search(line):
            found.append(f"line {number}: {line.strip()}")
    return found


def anchors(page: Path) -> set[str]:
    """The anchors GitHub gives the page's headings: lower case, punctuation dropped, spaces to
    hyphens, `-1`, `-2`, ... on repeats; lines inside code fences are not headings."""
    found: set[str] = set()
    seen: dict[str, int] = {}
    in_fence = False
    for line in page.read_text().splitlines():
        if line.startswith("```"):
            in_fence = not in_fence
        heading = None if in_fence else HEADING.match(line)
        if heading:
            slug = re.sub(r"[^\w\- ]", "", heading.group(1).strip().lower()).replace(" ", "-")
            repeat = seen.get(slug, 0)
            seen[slug] = repeat + 1
            found.add(slug if repeat == 0 else f"{slug}-{repeat}")
    return found


def test_the_check_finds_a_measured_section_and_a_dated_figure_but_not_a_measured_pose():
    old_text = ("## Measured (2-core shared CPU)\n\n"
                "Measured (2-core CPU, idle, 2026-11-29): 10.9 training steps/s at batch 64.\n"
                "| `ee_pose` | (T, 9) float32 | measured spoon pose before action t |\n"
                "## Benchmark\n")
    assert hand_written_measurements(old_text) == [
        "line 1: ## Measured (2-core shared CPU)",
        "line 3: Measured (2-core CPU, idle, 2026-11-29): 10.9 training steps/s at batch 64.",
    ]


@pytest.mark.parametrize("page", REFERENCE_PAGES, ids=lambda p: p.name)
def test_a_reference_page_holds_no_measurements(page):
    found = hand_written_measurements(page.read_text())
    assert not found, (f"docs/{page.name} holds measurements ({'; '.join(found)}): move performance figures to "
                       "docs/benchmarks.md under the script that makes them, earlier protocols' results to "
                       "docs/history.md, and link there")


@pytest.mark.parametrize("page", LINKED_PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_reaches_a_file_and_heading(page):
    broken = []
    for target in LINK.findall(page.read_text()):
        if re.match(r"[a-z]+:", target):  # https:, mailto:
            continue
        path, _, anchor = target.partition("#")
        linked = (page.parent / path).resolve() if path else page
        if not linked.exists():
            broken.append(f"{target} (no such file)")
        elif anchor and linked.suffix == ".md" and anchor not in anchors(linked):
            broken.append(f"{target} (no such heading)")
    assert not broken, f"{page.relative_to(ROOT)}: {', '.join(broken)}"
