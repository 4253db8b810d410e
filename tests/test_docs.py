"""The documentation's shape: a reference page says how a thing works and holds no measurement (a
measured number is rendered from a committed summary, between `<!-- generated: ... -->` markers, or
lives in benchmarks/README.md under the script that measures it); the user guide stays short; the
README keeps its limits; every relative link in the docs reaches an existing file and heading."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
# Measured figures live beside the scripts that make them (benchmarks/README.md). Generated results
# (docs/results.md's blocks, the studies' summaries) are rendered, and the lab notebook of earlier
# protocols lives in docs/archive/, outside docs/*.md.
REFERENCE_PAGES = sorted([ROOT / "README.md", *DOCS.glob("*.md")])
LINKED_PAGES = sorted([ROOT / "README.md", *DOCS.rglob("*.md"), *(ROOT / "studies").rglob("*.md"), ROOT / "benchmarks" / "README.md"])
# The user guide, docs/*.md, is read in one sitting: about 20,000 words at most.
GUIDE_WORDS = 20_000
README_LINES, README_PARAGRAPH_WORDS, RESULTS_LINES = 130, 90, 150

DATE = re.compile(r"\b20\d\d-\d\d-\d\d\b")
HEADING = re.compile(r"^#{1,6}\s+(.*)")
LINK = re.compile(r"\]\(([^)\s]+)\)")
FENCE = re.compile(r"^\s*(```|~~~)")
GENERATED = re.compile(r"<!-- generated: .*? -->.*?<!-- end generated -->", re.S)
CODE_SPAN = re.compile(r"``.*?``|`[^`\n]*`")
DECIMAL = r"[+\-−]?\d*\.\d+"
# The shapes a measured number takes in prose; a definition (a range, a layer size, a default)
# takes none of them.
MEASUREMENT = {
    "a count of a total": re.compile(r"\b\d+ (?:of|against|out of|instead of) (?:\w+'s )?\d+\b"),
    "a count before and after": re.compile(r"\b\d+ ?→ ?\d+\b"),
    "a p value": re.compile(r"\bp ?(?:[<=>≈] ?)?(?:0?\.\d+|1)(?![\w.])"),
    "an AUROC": re.compile(r"\bAUROC(?: of| at| is)? +0?\.\d+"),
    "an interval": re.compile(rf"\[ *{DECIMAL} ?%?, *{DECIMAL} ?%? *\]"),
    "a ratio": re.compile(r"(?<![\d.\-])\d+\.\d+x\b"),
    "a correlation": re.compile(rf"\b(?:Spearman|Pearson|correlation) +{DECIMAL}"),
    "a figure said to be measured": re.compile(r"\bMeasured\b|\bmeasured (?:under|on|with|at|in|before|after) "),
    "a date": DATE,
}


def prose_lines(text: str):
    """(line number, text) of each line of prose: generated blocks, code fences, indented code and
    inline code spans left out (a command's output or a config's value is not a claim)."""
    text = GENERATED.sub(lambda block: "\n" * block.group(0).count("\n"), text)
    in_fence = False
    for number, line in enumerate(text.splitlines(), start=1):
        if FENCE.match(line):
            in_fence = not in_fence
            continue
        if not in_fence and not line.startswith("    "):
            yield number, CODE_SPAN.sub("", line)


def hand_written_measurements(text: str) -> list[str]:
    """`line N: WHAT (MATCH)` for each hand-typed measurement in the prose of `text`: a count of a
    total, a p value, an AUROC, an interval, a ratio, a correlation, a date or a figure called
    measured (MEASUREMENT)."""
    found = []
    for number, line in prose_lines(text):
        for what, pattern in MEASUREMENT.items():
            match = pattern.search(line)
            if match:
                found.append(f"line {number}: {what} ({match.group(0)})")
    return found


def paragraphs(text: str) -> list[str]:
    """The prose paragraphs of a page: runs of non-blank lines outside code fences, tables and headings."""
    found, current, in_fence = [], [], False
    for line in text.splitlines() + [""]:
        if FENCE.match(line):
            in_fence = not in_fence
        if in_fence or FENCE.match(line) or not line.strip() or line.lstrip().startswith(("|", "#", "<!--")):
            if current:
                found.append(" ".join(current))
            current = []
        else:
            current.append(line.strip())
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


def test_the_check_finds_the_measurements_of_the_old_reference_pages_but_not_a_definition():
    # Lines of docs/evaluation.md and docs/predictor.md as they read before the study left them.
    old_text = ("## Measured (2-core shared CPU)\n\n"
                "asked for more than the Panda's joint speeds in 69 of DP's 100 protocol episodes\n"
                "episode peaked at 2.3x, its largest at 8x), and the simulated arm followed them.\n"
                "then lost food in 2 instead of 8, with the same scoops\n"
                "| carry set, chunk label | 0.524 [0.484, 0.563] | 0.561 [0.529, 0.595] |\n"
                "(16 → 23, p 0.25), and succeeded in 6 against 30\n"
                "ranks better (AUROC 0.616 on DP's chunks, 0.682 within a food)\n"
                "P(spill) tracks the chunk's position in the scoop (Spearman -0.91 and -0.93 within a food)\n"
                "Measured (2-core CPU, idle, 2026-11-29): 10.9 training steps/s at batch 64.\n")
    found = hand_written_measurements(old_text)
    assert [line.split(":")[0] for line in found] == [f"line {n}" for n in (1, 3, 4, 5, 6, 7, 7, 7, 8, 9, 10, 10)]
    definitions = ("| point encoder (DP3) | per-point MLP 3 -> 64 -> 128 with LayerNorm |\n"
                   "xyz min-max to [-1, 1], the pace 0.9-1.15x of the nominal scoop, `p < 0.05` in code\n"
                   "| `ee_pose` | (T, 9) float32 | measured spoon pose before action t |\n"
                   "```\ngrits-lab compare-runs A B   # 4 of 100 → 6, p 0.75\n```\n"
                   "<!-- generated: headline run -->\n| GRITS | 4.0% (4/100) | p 0.75 |\n<!-- end generated -->\n")
    assert hand_written_measurements(definitions) == []


@pytest.mark.parametrize("page", REFERENCE_PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_a_reference_page_holds_no_measurements(page):
    found = hand_written_measurements(page.read_text())
    assert not found, (f"{page.relative_to(ROOT)} holds hand-typed measurements ({'; '.join(found)}): render the "
                       "number from a committed summary (a `<!-- generated: ... -->` block), put a performance "
                       "figure in benchmarks/README.md under the script that makes it, or move a study's finding "
                       "to its studies/<name>/README.md, and link there")


# docs/cli.md is generated from the parser (tests/cli checks it is current): a reference looked up, not read.
GENERATED_PAGES = {"cli.md"}


def test_the_user_guide_is_read_in_one_sitting():
    words = {p.name: len(p.read_text().split()) for p in DOCS.glob("*.md") if p.name not in GENERATED_PAGES}
    assert sum(words.values()) <= GUIDE_WORDS, (
        f"docs/*.md hold {sum(words.values())} words, more than {GUIDE_WORDS}: "
        + ", ".join(f"{name} {n}" for name, n in sorted(words.items(), key=lambda item: -item[1])[:5]))


def test_the_paragraph_check_counts_prose_only():
    text = "# Title\n\none two\nthree\n\n```\nfour five six\n```\n| a | b |\n\n- seven\n"
    assert paragraphs(text) == ["one two three", "- seven"]


def test_the_readme_is_short_and_no_paragraph_runs_long():
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= README_LINES, f"README.md has {len(text.splitlines())} lines, more than {README_LINES}"
    long = [f"{len(p.split())} words: {p[:60]}..." for p in paragraphs(text) if len(p.split()) > README_PARAGRAPH_WORDS]
    assert not long, f"README.md paragraphs over {README_PARAGRAPH_WORDS} words: {'; '.join(long)}"


def test_the_readme_uses_no_term_of_the_study_it_does_not_define():
    # The study's words: a reader of the README meets none of them undefined.
    text = (ROOT / "README.md").read_text().lower()
    used = [term for term in ("horizon-label", "horizon label", "chunk-label", "chunk label", "recipe", "chain", "brim", "nudge")
            if term in text]
    assert not used, f"README.md uses {', '.join(used)}: the study's terms belong in studies/*/README.md"


def test_the_results_page_opens_with_its_answer_and_stays_short():
    text = (DOCS / "results.md").read_text()
    assert len(text.splitlines()) <= RESULTS_LINES, f"docs/results.md has {len(text.splitlines())} lines, more than {RESULTS_LINES}"
    first_block = text.split("<!-- generated: ", 1)
    assert len(first_block) == 2 and first_block[1].startswith("answer "), \
        "docs/results.md's first generated block is to be its answer (`<!-- generated: answer ... -->`)"
    assert not [p for p in paragraphs(first_block[0]) if not p.startswith("#")][1:], \
        "docs/results.md: at most one paragraph comes before the answer"


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
