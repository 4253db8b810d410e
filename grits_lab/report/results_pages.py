"""Render the results pages (README, docs/results.md, the studies' pages) from the committed summaries.

An experiment is a folder of committed summaries, found by its name in one of SUMMARY_DIRS:
`studies/STUDY/summaries/NAME/` (the current protocol's runs, one study a question) or
`docs/archive/NAME/` (runs of a superseded protocol version). Names are unique across them.

A page holds generated blocks between two markers; everything outside them is hand-written and kept:

    <!-- generated: KIND [EXPERIMENT] -->
    ...replaced by `grits-lab results render`...
    <!-- end generated -->

KIND is one of BLOCKS: `outcomes`, `stages`, `provenance`, `headline` and `claims` read the
summary files of the experiment's folder (grits_lab/report/summary.py); `comparison` reads
the paired comparison `grits-lab compare-runs` writes there; `paired` every method against Diffusion
Policy on the same episodes; `per_food` each method's spills and successes food by food (the page's
episodes.csv); `sweep_reference` a sweep's front against its reference methods and
`sweep_trials` every one of its trials (a sweep's summary: `grits-lab report results/sweeps/NAME
--summary-to ...`); `answer NAME+NAME...` the three sentences a results page opens with (does
GRITS spill less than Diffusion Policy during the scoop, by how much, on how many chains and
seeds), each NAME one chain of checkpoints; `shift BEFORE..AFTER[+AFTER...]`
sets each method's outcomes in one summary beside another's (a protocol before and after a change,
whose records need not exist any more); `index [STUDY|archive]` lists the experiment folders of one
study, of the archive, or (no name) of every study. `grits-lab results
check` (and tests/report/test_results_pages.py) fails when a page differs from what its summaries
render.
"""

from __future__ import annotations

import json
import math
import os
import re
from functools import partial
from pathlib import Path
from typing import Callable

import pandas as pd

from grits_lab.errors import InputError
from grits_lab.intervals import format_percent
from grits_lab.markdown import markdown_table
from grits_lab.records import OUTCOME_COLUMNS
from grits_lab.report.run_compare import COMPARISON_FILE, PAIRED_METHODS_FILE, comparison_markdown, paired_methods_markdown
from grits_lab.report.spill_tables import CAUSE_NAMES, STAGE_NAMES
from grits_lab.report.run_records import SWEEP_REFERENCE_FILE
from grits_lab.report.summary import CLAIMS_FILE, PROVENANCE_FILE, STAGES_FILE, SUMMARY_FILE
from grits_lab.report.sweep import sweep_reference_table
from grits_lab.report.vocabulary import MAIN_METHODS, PAPER_RESULTS, UNSEEN_FOODS, food_display, ordered
from grits_lab.sim.spill_metrics import SPILL_CAUSES, SPILL_STAGES

STUDIES_DIR = Path("studies")
ARCHIVE_DIR = Path("docs") / "archive"
# Where experiment folders live, as globs from the repository's root: every study's summaries, then the archive.
SUMMARY_DIRS = (str(STUDIES_DIR / "*" / "summaries"), str(ARCHIVE_DIR))
PAGE_FILE = "README.md"
OPEN_MARKER, END_MARKER = "<!-- generated: KIND [NAME] -->", "<!-- end generated -->"
_MARKER_LINE = re.compile(r"^\s*<!--\s*(end\s+)?generated\b.*$", re.M)  # anything that looks like a marker
_OPEN_LINE = re.compile(r"<!-- generated: [a-z_]+(?: [A-Za-z0-9_.+-]+)? -->")
BLOCK = re.compile(r"(<!-- generated: (?P<kind>[a-z_]+)(?: (?P<name>[A-Za-z0-9_.+-]+))? -->\n)(?P<body>.*?)(<!-- end generated -->)", re.S)
OUTCOME_HEADERS = {
    "task_success": "Task success",
    "spillage": "Spill during the scoop",
    "scoop_failure": "Scoop failure",
    "spill_after_scoop": "Spill after the scoop",
    "delivered": "Lifted food delivered",
    "reach_check_failed": "Reach check failed",
    "error": "Errors",
}
# The shift block's outcomes: the paper's three, then where the food was lost after the scoop, stage by stage.
SHIFT_HEADERS = {
    **{o: OUTCOME_HEADERS[o] for o in ("task_success", "spillage", "scoop_failure", "spill_after_scoop")},
    "spill_lift": "in the lift",
    "spill_carry": "in the carry",
    "spill_pour": "in the pour",
    "spill_after_pour": "after the pour",
    "delivered": "Lifted food delivered",
}


def experiment_folders(root: str | Path) -> dict[str, Path]:
    """Every experiment's name -> its folder, studies first, then the archive (SUMMARY_DIRS).
    InputError when two folders share a name (a block could not tell which one it means)."""
    root = Path(root)
    found: dict[str, Path] = {}
    for pattern in SUMMARY_DIRS:
        for folder in sorted(root.glob(f"{pattern}/*/")):
            if folder.name in found:
                raise InputError(f"two experiments are named `{folder.name}`: {found[folder.name]} and {folder}")
            found[folder.name] = folder
    return found


def pages(root: str | Path) -> list[Path]:
    """The pages that may hold generated blocks: README.md, docs/results.md, every study's README,
    the archive's README and every experiment's page."""
    root = Path(root)
    found = [root / "README.md", root / "docs" / "results.md", *sorted((root / STUDIES_DIR).glob(f"*/{PAGE_FILE}")),
             root / ARCHIVE_DIR / PAGE_FILE, *(folder / PAGE_FILE for folder in experiment_folders(root).values())]
    return [p for p in found if p.is_file()]


def render_page(text: str, page: Path, root: str | Path) -> str:
    """`text` (the page at `page`) with every generated block rendered afresh; the rest unchanged.
    InputError naming the page and line when its markers do not pair (check_markers)."""
    root = Path(root)
    check_markers(text, page)

    def block(match: re.Match[str]) -> str:
        kind, name = match["kind"], match["name"]
        if kind not in BLOCKS:
            raise InputError(f"{page}: unknown generated block `{kind}`; one of {', '.join(BLOCKS)}")
        if kind != "index" and not name:
            raise InputError(f"{page}: the generated block `{kind}` needs an experiment name")
        try:
            body = BLOCKS[kind](root, name, page.parent)
        except _NotSummarised as missing:
            body = str(missing)
        return f"{match.group(1)}{body.rstrip()}\n{match.group(5)}"

    return BLOCK.sub(block, text)


def check_markers(text: str, page: Path) -> None:
    """Every block marker of `text` parses and they pair in order, open then end: a block left
    open would otherwise reach the next block's end and take the hand-written text between them.
    InputError `PAGE:LINE: ...` saying which marker to add or fix; nothing is rendered then."""
    opened: tuple[int, str] | None = None
    for match in _MARKER_LINE.finditer(text):
        line, marker = text.count("\n", 0, match.start()) + 1, match.group(0).strip()
        if marker == END_MARKER:
            if opened is None:
                raise InputError(f"{page}:{line}: `{END_MARKER}` closes no block; remove it or add its "
                                 f"`{OPEN_MARKER}` above the generated text")
            opened = None
        elif _OPEN_LINE.fullmatch(marker):
            if opened is not None:
                raise InputError(f"{page}:{opened[0]}: `{opened[1]}` has no `{END_MARKER}` before the next block "
                                 f"(line {line}); add it where the generated text ends")
            opened = (line, marker)
        else:
            raise InputError(f"{page}:{line}: a block marker that does not parse: `{marker}`; write `{OPEN_MARKER}` "
                             f"or `{END_MARKER}` on a line of its own")
    if opened is not None:
        raise InputError(f"{page}:{opened[0]}: `{opened[1]}` has no `{END_MARKER}`; add it where the generated text ends")


def render_all(root: str | Path) -> dict[Path, str]:
    """Every page with generated blocks -> its rendered text."""
    rendered = {}
    for page in pages(root):
        text = page.read_text()
        check_markers(text, page)
        if BLOCK.search(text):
            rendered[page] = render_page(text, page, root)
    return rendered


def drifted(root: str | Path) -> list[Path]:
    """The pages whose generated blocks differ from what the committed summaries render."""
    return [page for page, text in render_all(root).items() if page.read_text() != text]


def write_all(root: str | Path) -> list[Path]:
    """Rewrite the pages that drifted; returns them."""
    from grits_lab.io import write_text_atomic

    changed = drifted(root)
    rendered = render_all(root)
    for page in changed:
        write_text_atomic(page, rendered[page])
    return changed


# --- reading an experiment's files ------------------------------------------------------------

class _NotSummarised(Exception):
    """An experiment folder without its summary yet: the block says so and names the command."""


def _experiment(root: Path, name: str) -> Path:
    """The experiment NAME's folder; InputError when no folder has that name (a misspelt name)."""
    folder = experiment_folders(root).get(name)
    if folder is None:
        raise InputError(f"no experiment `{name}`: no folder of that name in {' or '.join(SUMMARY_DIRS)}")
    return folder


def _folder(root: Path, name: str, needs: str = SUMMARY_FILE) -> Path:
    """The experiment NAME's folder (`experiment_folders`) holding the file `needs`; InputError when no
    folder has that name (a misspelt name), _NotSummarised naming the command that writes a missing file."""
    folder = _experiment(root, name)
    if not (folder / needs).is_file():
        there = folder.relative_to(root)
        writer = (f"grits-lab compare-runs BEFORE_RUN AFTER_RUN --output-dir {there}" if needs == COMPARISON_FILE
                  else f"grits-lab report RUN_DIR --summary-to {there}")
        raise _NotSummarised(f"No {'comparison' if needs == COMPARISON_FILE else 'summary'} yet: `{writer}`, "
                             "then `grits-lab results render`.")
    return folder


def _summary(root: Path, name: str) -> pd.DataFrame:
    return pd.read_csv(_folder(root, name) / SUMMARY_FILE, keep_default_na=False, na_values=[""])


def _merged_summary(root: Path, names: str) -> pd.DataFrame:
    """The summaries of `NAME+NAME...` as one, each method's rows from the first summary holding it
    (a protocol whose methods were run into several experiments), in the column `experiment`."""
    parts, seen = [], set()
    for name in names.split("+"):
        summary = _summary(root, name)
        parts.append(summary[~summary["method"].isin(seen)].assign(experiment=name))
        seen |= set(summary["method"])
    return pd.concat(parts, ignore_index=True)


def _provenance(root: Path, name: str) -> dict:
    return json.loads((_folder(root, name) / PROVENANCE_FILE).read_text())


def _cell(row: pd.Series | None, interval: bool = True) -> str:
    if row is None or not row["n"]:
        return "—"
    k, n = int(row["k"]), int(row["n"])
    bounds = f" [{format_percent(float(row['ci_low']))}, {format_percent(float(row['ci_high']))}]" if interval else ""
    return f"{format_percent(k / n)}{bounds} ({k}/{n})"


def _methods(summary: pd.DataFrame) -> list[tuple[str, str]]:
    return list(dict.fromkeys(zip(summary["method"], summary["method_name"])))


def _lookup(summary: pd.DataFrame, method: str, outcome: str) -> pd.Series | None:
    rows = summary[(summary["method"] == method) & (summary["outcome"] == outcome)]
    return rows.iloc[0] if len(rows) else None


# --- the blocks ---------------------------------------------------------------------------------

def outcomes_block(root: Path, name: str, here: Path) -> str:
    """Per method: episodes and every outcome the records give, rate [Wilson 95 %] (k/n)."""
    summary = _summary(root, name)
    shown = [o for o in OUTCOME_HEADERS if o in set(summary["outcome"])]
    rows = []
    for method, method_name in _methods(summary):
        episodes = _lookup(summary, method, "task_success")
        rows.append([method_name, str(int(episodes["n"])) if episodes is not None else "—",
                     *(_cell(_lookup(summary, method, o)) for o in shown)])
    table = markdown_table(["Method", "Episodes", *(OUTCOME_HEADERS[o] for o in shown)], rows)
    return (f"{table}\n\nRate [Wilson 95 % interval] (k/n). Lifted food delivered: of the episodes that lifted food; "
            f"reach check failed: of the transfers checked. Files: [{SUMMARY_FILE}]({_link(root, name, SUMMARY_FILE, here)}), "
            f"[{PROVENANCE_FILE}]({_link(root, name, PROVENANCE_FILE, here)}).")


def stages_block(root: Path, name: str, here: Path) -> str:
    """Stages in which a particle was lost, per method: episodes (particles) for each cause."""
    stages = pd.read_csv(_folder(root, name) / STAGES_FILE)
    if stages.empty:
        return "The records predate the per-stage attribution (`spilled_<stage>_<cause>` columns)."
    rows = []
    for (method, method_name), group in stages.groupby(["method", "method_name"], sort=False):
        n = int(group["episodes"].iloc[0])
        for stage in SPILL_STAGES:
            cells = group[group["stage"] == stage].set_index("cause")
            if cells["particles"].sum() == 0:
                continue
            rows.append([f"{method_name}, {n}", STAGE_NAMES[stage],
                         *(f"{int(cells.at[c, 'episodes_k'])} ({int(cells.at[c, 'particles'])})" if cells.at[c, "particles"] else "0"
                           for c in SPILL_CAUSES)])
    if not rows:
        return "No particle was spilled in any episode."
    table = markdown_table(["Method, episodes", "Stage", *(CAUSE_NAMES[c].lower() for c in SPILL_CAUSES)], rows, right=2)
    return f"{table}\n\nEpisodes (particles) that lost food each way, stages with a loss only. File: [{STAGES_FILE}]({_link(root, name, STAGES_FILE, here)})."


PER_FOOD_OUTCOMES = {"spillage": "spill during the scoop", "spill_before_pour": "spill before the pour",
                     "task_success": "task success"}


def per_food_block(root: Path, name: str, here: Path) -> str:
    """Per outcome of PER_FOOD_OUTCOMES a table, foods by method, of the episodes with it as "k/n"
    (the page's episodes.csv; episodes with an error left out), the paper's foods in its order and
    every food last: where a method's spills were, or were removed, food by food."""
    from grits_lab.report.run_compare import with_paired_outcomes
    from grits_lab.report.run_records import PAGE_RECORDS_FILE, load_run
    from grits_lab.report.spill_tables import has_attribution
    from grits_lab.report.tables import all_variants

    folder = _folder(root, name, needs=PAGE_RECORDS_FILE)
    episodes = load_run(folder).episodes
    if not has_attribution(episodes):
        return "The records predate the per-stage attribution (`spilled_<stage>_<cause>` columns)."
    names = dict(all_variants(episodes))  # the outcomes block's columns, a method that only errored included
    episodes = with_paired_outcomes(episodes[~episodes["is_error"].astype(bool)])
    if episodes.empty:
        return "Every episode ended with an error."
    foods = [*ordered(episodes["food_key"].unique(), tuple(UNSEEN_FOODS)), None]
    parts = []
    for outcome, label in PER_FOOD_OUTCOMES.items():
        rows = []
        for food in foods:
            of_food = episodes if food is None else episodes[episodes["food_key"] == food]
            cells = []
            for variant in names:
                held = of_food[of_food["variant"] == variant]
                cells.append(f"{int(held[outcome].astype(bool).sum())}/{len(held)}" if len(held) else "—")
            rows.append(["Every food" if food is None else food_display(food, long=True)] + cells)
        parts.append(f"*{label[0].upper()}{label[1:]}*\n\n{markdown_table(['Food', *names.values()], rows)}")
    return ("\n\n".join(parts) + "\n\nEpisodes with each outcome of the food's episodes without an error (k/n). Spill "
            "before the pour: food lost in the scoop, lift or carry. "
            f"File: [{PAGE_RECORDS_FILE}]({_link(root, name, PAGE_RECORDS_FILE, here)}).")


def provenance_block(root: Path, name: str, here: Path) -> str:
    """Protocol, commits, machine, dates, wall time, checkpoints and episodes per method, as bullets."""
    p = _provenance(root, name)
    machine = p.get("machine", {})
    packages = machine.get("packages", {})
    shown = ", ".join(f"{k} {packages[k]}" for k in ("python", "torch", "numpy", "pybullet") if k in packages)
    # the commits the records name (several where runs at several commits joined), else the run's provenance
    named = sorted({c for method in p.get("methods", {}).values() for c in method.get("code commits", [])})
    latest = p.get("records' code commit")
    records_commit = _commit_list(named) or (f"`{latest}`" if latest else None)
    kernels = machine.get("cpu kernels (episodes)", {})
    cpu = (f"; CPU {machine['cpu']}" if machine.get("cpu") else "") + (
        "; CPU kernels " + ", ".join(f"`{k}` ({n} episode{'' if n == 1 else 's'})" for k, n in kernels.items()) if kernels else "")
    started, host = p.get("run started (UTC)"), machine.get("host")
    lines = [
        f"- Protocol: {', '.join(p.get('protocol', [])) or 'not recorded'}; records' code: {_recorded(records_commit, str(records_commit))}.",
        f"- Machine: host {_recorded(host, f'`{host}`')}{'; ' + shown if shown else ''}{cpu}; "
        f"run started {_recorded(started, f'{started} UTC')}.",
        f"- Episode wall time, summed: {_duration(p.get('episode wall time (s, summed)'))}.",
    ]
    for method in p.get("methods", {}).values():
        digests = "; ".join(f"{key} `{', '.join(values)}`" for key, values in method.get("checkpoint digests (sha256, first 16)", {}).items())
        trials = method.get("trials", [])
        commits = _commit_list(method.get("code commits", []))
        lines.append(f"- {method['name']}: {method['episodes']} episodes, {method['foods']} foods, levels {', '.join(method['levels'])}, "
                     f"trials {_span(trials)}" + (f"; checkpoints {digests}" if digests else "")
                     + (f"; code {commits}" if commits else "") + ".")
    commit = p.get("summary code commit")
    lines.append(f"- Summary written by `{p.get('command')}` (code {_recorded(commit, f'`{commit}`')}).")
    return "\n".join(lines)


def _commit_list(commits: list[str]) -> str:
    """Commits as the page lists them: each `_short_commit`, in code quotes, comma-separated ("" for none)."""
    return ", ".join(f"`{_short_commit(c)}`" for c in commits)


def _short_commit(commit: str) -> str:
    """A commit as the page names it: the sha's first 12 characters, with any suffix the record kept
    ("(with uncommitted changes)"); "unknown ..." as recorded."""
    sha, _, rest = commit.partition(" ")
    if len(sha) == 40 and all(c in "0123456789abcdef" for c in sha):
        return sha[:12] + (f" {rest}" if rest else "")
    return commit


def _recorded(value: object, shown: str) -> str:
    """`shown` where the provenance recorded `value`; "not recorded" where it holds none (a sweep's summary)."""
    return shown if value else "not recorded"


def headline_block(root: Path, name: str, here: Path) -> str:
    """The paper's Fig. 5 methods: episodes and the three outcomes, this simulation beside the paper's real robot.
    `NAME+NAME...` takes each method from the first of the experiments that holds it."""
    summary = _merged_summary(root, name)
    methods = dict(_methods(summary))
    order = [m for m in MAIN_METHODS if m in methods] + [m for m in methods if m not in MAIN_METHODS]
    rows = []
    for method in order:
        episodes = _lookup(summary, method, "task_success")
        paper = PAPER_RESULTS.get(method.split("[")[0], {})
        rows.append([methods[method], str(int(episodes["n"])) if episodes is not None else "—",
                     *(part for o in OUTCOME_COLUMNS for part in (_cell(_lookup(summary, method, o), interval=False),
                                                                    format_percent(paper.get(o)) if o in paper else "—"))])
    header = ["Method", "Episodes"] + [f"{OUTCOME_HEADERS[o]}, {who}" for o in OUTCOME_COLUMNS for who in ("sim", "paper")]
    return markdown_table(header, rows)


def claims_block(root: Path, name: str, here: Path) -> str:
    """The report's claims table (the paper's claims beside these records), as the summary holds it."""
    claims = pd.read_csv(_folder(root, name) / CLAIMS_FILE, keep_default_na=False)
    return markdown_table(list(claims.columns), [list(map(str, row)) for row in claims.itertuples(index=False)], right=99)


def comparison_block(root: Path, name: str, here: Path) -> str:
    """Two runs on the same seeds, paired (`grits-lab compare-runs ... --output-dir FOLDER`)."""
    table = pd.read_csv(_folder(root, name, needs=COMPARISON_FILE) / COMPARISON_FILE)
    return f"{comparison_markdown(table)} File: [{COMPARISON_FILE}]({_link(root, name, COMPARISON_FILE, here)})."


def paired_block(root: Path, name: str, here: Path) -> str:
    """Every method against Diffusion Policy on the same episodes, and a method's settings against its
    reference setting, as the summary holds it (paired.csv)."""
    table = pd.read_csv(_folder(root, name, needs=PAIRED_METHODS_FILE) / PAIRED_METHODS_FILE)
    head, rows, caption = paired_methods_markdown(table)
    return f"{markdown_table(head, rows, right=head.index('Paired episodes'))}\n\n{caption} File: [{PAIRED_METHODS_FILE}]({_link(root, name, PAIRED_METHODS_FILE, here)})."


def sweep_reference_block(root: Path, name: str, here: Path, every_trial: bool = False) -> str:
    """A sweep's success-spillage front (`every_trial`: every paired trial, by rho) against its
    reference methods (unguided DP) on the same validation episodes, as the summary holds it
    (reference.csv: grits_lab/tune/reference.py)."""
    table = sweep_reference_table(pd.read_csv(_folder(root, name, needs=SWEEP_REFERENCE_FILE) / SWEEP_REFERENCE_FILE),
                                  every_trial=every_trial)
    if table is None:
        return f"{SWEEP_REFERENCE_FILE} holds no pairing (empty, or not the table grits_lab/tune/reference.py writes)."
    shown = table.display
    if shown.empty:
        return f"No trial on the front is paired in {SWEEP_REFERENCE_FILE}."
    return (f"{markdown_table(list(shown.columns), shown.astype(str).values.tolist())}\n\n{table.caption} "
            f"File: [{SWEEP_REFERENCE_FILE}]({_link(root, name, SWEEP_REFERENCE_FILE, here)}).")


def shift_block(root: Path, name: str, here: Path) -> str:
    """`BEFORE..AFTER[+AFTER...]`: per method of BEFORE's summary that an AFTER summary holds (the first
    that does), each outcome of SHIFT_HEADERS as "k/n → k/n". Unpaired: the two summaries' episodes
    share seeds only where their pages say so."""
    before_name, sep, after_names = name.partition("..")
    if not sep or not after_names:
        raise InputError(f"the shift block needs BEFORE..AFTER[+AFTER...], got `{name}`")
    before = _summary(root, before_name)
    after = _merged_summary(root, after_names)
    source = dict(zip(after["method"], after["experiment"]))
    rows = []
    for method, method_name in _methods(before):
        if method not in source:
            continue
        cells = []
        for outcome in SHIFT_HEADERS:
            was, now = _lookup(before, method, outcome), _lookup(after, method, outcome)
            cells.append(" → ".join("—" if r is None else f"{int(r['k'])}/{int(r['n'])}" for r in (was, now)))
        rows.append([method_name, *cells, f"[{source[method]}]({_link(root, source[method], PAGE_FILE, here)})"])
    if not rows:
        return f"No method of {before_name} is in {', '.join(after_names.split('+'))}."
    table = markdown_table(["Method", *SHIFT_HEADERS.values(), "After"], rows)
    return (f"{table}\n\nEpisodes with each outcome (k/n), [{before_name}]"
            f"({_link(root, before_name, PAGE_FILE, here)}) → the run named under After; "
            "in the lift, carry, pour and after the pour: episodes with a particle lost in that stage (an episode may lose "
            "food in more than one); lifted food delivered: of the episodes that lifted food. Counts from the two runs' "
            "summaries, not paired episode by episode.")


def index_block(root: Path, name: str | None, here: Path) -> str:
    """The experiment folders of study `name` (`archive`: the archive's; none: every study's, study by
    study): each page's title, protocol and episodes per method."""
    if name == "archive":
        folders = sorted((root / ARCHIVE_DIR).glob("*/"))
    elif name:
        if not (root / STUDIES_DIR / name).is_dir():
            raise InputError(f"the index block names no study `{name}`: {root / STUDIES_DIR / name} does not exist")
        folders = sorted((root / STUDIES_DIR / name / "summaries").glob("*/"))
    else:
        folders = sorted((root / STUDIES_DIR).glob("*/summaries/*/"))
    rows = []
    for folder in folders:
        page = folder / PAGE_FILE
        if not page.is_file():
            continue
        title = next((line[2:].strip() for line in page.read_text().splitlines() if line.startswith("# ")), folder.name)
        link = os.path.relpath(page, here)
        if (folder / PROVENANCE_FILE).is_file():
            p = json.loads((folder / PROVENANCE_FILE).read_text())
            protocol = ", ".join(p.get("protocol", []))
            episodes = ", ".join(f"{m['name']} {m['episodes']}" for m in p.get("methods", {}).values())
        else:
            protocol, episodes = "—", "no summary yet"
        rows.append([f"[{folder.name}]({link})", title, protocol, episodes])
    return markdown_table(["Experiment", "Question", "Protocol", "Episodes"], rows, right=99)


ANSWER_METHOD, ANSWER_REFERENCE, SIGNIFICANCE = "grits", "dp", 0.05


def answer_block(root: Path, name: str, here: Path) -> str:
    """`NAME+NAME...`, each experiment one chain (a policy and predictor trained from nothing): three
    sentences from their paired.csv, summary.csv and provenance.json. Whether GRITS (the paper's
    method, `grits`) spills during the scoop less than Diffusion Policy on the same seeds, by the
    exact sign test at p < SIGNIFICANCE on each chain; by how much, each rate with its Wilson 95 %
    interval; on how many chains (DP's policy checkpoints) and paired seeds. InputError when an
    experiment holds no `grits` against `dp` pairing."""
    rows = []
    for experiment in name.split("+"):
        paired_file = _folder(root, experiment, needs=PAIRED_METHODS_FILE) / PAIRED_METHODS_FILE
        paired = pd.read_csv(paired_file)
        pair = paired[(paired["reference"] == ANSWER_REFERENCE) & (paired["method"] == ANSWER_METHOD)]
        if pair.empty:
            raise InputError(f"{paired_file.relative_to(root)}: no `{ANSWER_METHOD}` paired with "
                             f"`{ANSWER_REFERENCE}`, which the answer block reads")
        summary, provenance = _summary(root, experiment), _provenance(root, experiment)
        reference = provenance["methods"][ANSWER_REFERENCE]
        rows.append({"experiment": experiment, "pair": pair.iloc[0],
                     "grits": _lookup(summary, ANSWER_METHOD, "spillage"), "dp": _lookup(summary, ANSWER_REFERENCE, "spillage"),
                     "policy": ", ".join(reference.get("checkpoint digests (sha256, first 16)", {}).get("policy", [])) or "not recorded",
                     "levels": tuple(reference["levels"]), "foods": int(reference["foods"])})
    fewer = [r for r in rows if r["pair"]["spillage_after"] < r["pair"]["spillage_before"] and r["pair"]["spillage_p"] < SIGNIFICANCE]
    more = [r for r in rows if r["pair"]["spillage_after"] > r["pair"]["spillage_before"] and r["pair"]["spillage_p"] < SIGNIFICANCE]
    verdict = ("Yes" if len(fewer) == len(rows) else "Not measurably" if not fewer else f"On {len(fewer)} of {len(rows)} chains")
    levels = sorted({level for r in rows for level in r["levels"]})
    does = (f"Does GRITS spill less than Diffusion Policy during the scoop in this simulation, at the levels "
            f"{', '.join(levels)}? {verdict}: the exact sign test on the same seeds gives p < {SIGNIFICANCE} for fewer "
            f"spills on {len(fewer)} of {len(rows)} chains" + (f", and for more on {len(more)}" if more else "") + ".")
    how_much = "By how much: GRITS against DP spills during the scoop in " + "; ".join(
        f"{_cell(r['grits'])} against {_cell(r['dp'])} on [{r['experiment']}]({_link(root, r['experiment'], PAGE_FILE, here)}) "
        f"(paired {int(r['pair']['spillage_after'])} against {int(r['pair']['spillage_before'])}, p {float(r['pair']['spillage_p']):.2g})"
        for r in rows) + "."
    policies = ", ".join(f"`{r['policy']}`" for r in rows)
    seeds = [int(r["pair"]["paired"]) for r in rows]
    on_what = (f"On {len(rows)} chain{'' if len(rows) == 1 else 's'}, each a policy and predictor trained from nothing "
               f"(DP's policy checkpoints {policies}), and {sum(seeds)} paired seeds ({', '.join(map(str, seeds))}) of "
               f"{max(r['foods'] for r in rows)} unseen foods; rates are k/n with Wilson 95 % intervals.")
    return f"{does} {how_much} {on_what}"


BLOCKS: dict[str, Callable[[Path, str, Path], str]] = {
    "outcomes": outcomes_block,
    "stages": stages_block,
    "provenance": provenance_block,
    "headline": headline_block,
    "claims": claims_block,
    "comparison": comparison_block,
    "paired": paired_block,
    "per_food": per_food_block,
    "shift": shift_block,
    "sweep_reference": sweep_reference_block,
    "sweep_trials": partial(sweep_reference_block, every_trial=True),
    "index": index_block,
    "answer": answer_block,
}


def _link(root: Path, name: str, file: str, here: Path) -> str:
    """The relative link from the folder `here` to `file` in the experiment NAME's folder."""
    return os.path.relpath(_experiment(root, name) / file, here)


def _span(trials: list[int]) -> str:
    if not trials:
        return "not recorded"
    if trials == list(range(trials[0], trials[-1] + 1)) and len(trials) > 1:
        return f"{trials[0]}-{trials[-1]}"
    return ", ".join(map(str, trials))


def _duration(seconds: float | None) -> str:
    if seconds is None or (isinstance(seconds, float) and math.isnan(seconds)):
        return "not recorded"
    minutes, rest = divmod(int(round(seconds)), 60)
    hours, minutes = divmod(minutes, 60)
    return f"{hours} h {minutes:02d} min" if hours else f"{minutes} min {rest:02d} s"
