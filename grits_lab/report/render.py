"""Writers: one report model rendered as Markdown, LaTeX (booktabs), CSV and one self-contained HTML page.

The report model is a list of Sections holding tables, figures and preformatted text; each
writer walks the same model, so the formats cannot disagree about what the report contains.
The HTML page embeds its figures as base64 data URIs and its style inline: it opens offline,
can be mailed as one file, and references nothing outside itself, except the videos of
`grits-lab report --videos`, which sit beside it in `videos/` (the folder travels as one).
Words in tables wrap and numbers never break, so tables narrow to a laptop's window; a table
split per method (`ReportTable.parts`) shows each part under its subtitle; anything still too
wide scrolls inside its own box. Lists of missing cells are collapsed.
"""

from __future__ import annotations

import base64
import html
import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Union

import pandas as pd

from grits_lab.io import write_text_atomic
from grits_lab.report.tables import ReportTable
from grits_lab.report.videos import VideoRow
from grits_lab.report.vocabulary import MISSING


@dataclass
class ReportFigure:
    key: str
    title: str
    caption: str
    path: Path


@dataclass
class Preformatted:
    title: str
    text: str
    language: str = ""


@dataclass
class Collapsed:
    """Lines a reader opens when needed (e.g. the list of missing cells), under a one-line summary."""

    summary: str
    lines: list[str]


@dataclass
class Section:
    title: str
    items: list[Union[ReportTable, ReportFigure, Preformatted, Collapsed, VideoRow, str]] = field(default_factory=list)


def is_missing_note(note: str) -> bool:
    return note.startswith("Missing")


def write_csv(table: ReportTable, path: Path) -> Path:
    write_text_atomic(path, table.data.to_csv(index=False))
    return path


def table_frames(table: ReportTable) -> list[tuple[str, pd.DataFrame]]:
    """What a reader sees of `table`: its narrower parts under their subtitles, else the whole display."""
    if table.parts:
        return table.parts
    return [("", table.display if not table.display.empty else pd.DataFrame({"": [MISSING]}))]


def table_latex(table: ReportTable) -> str:
    """A booktabs table environment (one tabular per part); cells and headers escaped for LaTeX."""
    bodies = []
    for subtitle, frame in table_frames(table):
        styler = frame.style.hide(axis="index").format(escape="latex").format_index(escape="latex", axis=1)
        body = styler.to_latex(hrules=True, column_format="l" * frame.shape[1])
        heading = f"\\textbf{{{_latex_escape(subtitle)}}}\\\\\n" if subtitle else ""
        bodies.append(f"{heading}\\resizebox{{\\linewidth}}{{!}}{{%\n{body}}}\n")
    caption = _latex_escape(f"{table.title}. {table.caption}")
    return (
        "% needs \\usepackage{booktabs,graphicx}\n"
        "\\begin{table}[t]\n\\centering\n"
        f"\\caption{{{caption}}}\n\\label{{tab:{table.key}}}\n"
        + "\\medskip\n".join(bodies)
        + "\\end{table}\n"
    )


def render_markdown(title: str, sections: list[Section], out_dir: Path) -> str:
    lines = [f"# {title}", ""]
    for section in sections:
        lines += [f"## {section.title}", ""]
        for item in section.items:
            if isinstance(item, ReportTable):
                lines += [f"### {item.title}", "", item.caption, ""]
                for subtitle, frame in table_frames(item):
                    lines += ([f"#### {subtitle}", ""] if subtitle else []) + [_markdown_table(frame), ""]
                lines += [f"- {note}" for note in item.notes]
                lines += [f"- Files: csv/{item.key}.csv, latex/{item.key}.tex", ""]
            elif isinstance(item, ReportFigure):
                rel = item.path.relative_to(out_dir) if item.path.is_relative_to(out_dir) else item.path
                lines += [f"![{item.title}]({rel})", "", f"*{item.title}.* {item.caption}", ""]
            elif isinstance(item, Preformatted):
                lines += [f"**{item.title}**", "", f"```{item.language}", item.text.rstrip(), "```", ""]
            elif isinstance(item, Collapsed):
                lines += [f"**{item.summary}**", ""] + [f"- {line}" for line in item.lines] + [""]
            elif isinstance(item, VideoRow):
                lines += [f"**{item.title}**", ""]
                lines += [f"- [{v.path}]({v.path}): {v.caption}" if v.path else f"- {v.caption}" for v in item.videos] + [""]
            else:
                lines += [item, ""]
    return "\n".join(lines).rstrip() + "\n"


def render_html(title: str, sections: list[Section]) -> str:
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f"<title>{html.escape(title)}</title>",
        f"<style>{_CSS}</style></head><body>",
        f"<h1>{html.escape(title)}</h1>",
        '<nav><ol>' + "".join(f'<li><a href="#s{i}">{html.escape(s.title)}</a></li>' for i, s in enumerate(sections)) + "</ol></nav>",
    ]
    for i, section in enumerate(sections):
        parts.append(f'<section id="s{i}"><h2>{html.escape(section.title)}</h2>')
        for item in section.items:
            if isinstance(item, ReportTable):
                parts.append(f"<h3>{html.escape(item.title)}</h3><p class=caption>{html.escape(item.caption)}</p>")
                for subtitle, frame in table_frames(item):
                    if subtitle:
                        parts.append(f"<h4>{html.escape(subtitle)}</h4>")
                    parts.append(f'<div class="scroll">{_html_table(frame)}</div>')
                notes = [n for n in item.notes if not is_missing_note(n)]
                missing = [n for n in item.notes if is_missing_note(n)]
                if notes:
                    parts.append("<ul class=notes>" + "".join(f"<li>{html.escape(n)}</li>" for n in notes) + "</ul>")
                if missing:
                    parts.append(_details(f"Missing data in this table ({len(missing)} notes)", missing))
            elif isinstance(item, ReportFigure):
                encoded = base64.b64encode(item.path.read_bytes()).decode("ascii")
                parts.append(
                    f'<figure><img alt="{html.escape(item.title)}" src="data:image/png;base64,{encoded}">'
                    f"<figcaption><b>{html.escape(item.title)}.</b> {html.escape(item.caption)}</figcaption></figure>"
                )
            elif isinstance(item, Preformatted):
                parts.append(f"<details><summary>{html.escape(item.title)}</summary><pre>{html.escape(item.text)}</pre></details>")
            elif isinstance(item, Collapsed):
                parts.append(_details(item.summary, item.lines))
            elif isinstance(item, VideoRow):
                parts.append(f'<h3>{html.escape(item.title)}</h3><div class="videos">')
                for video in item.videos:
                    player = (f'<video controls muted loop playsinline preload="metadata" src="{html.escape(video.path)}"></video>'
                              if video.path else '<div class="novideo">not replayed</div>')
                    parts.append(f"<figure>{player}<figcaption>{html.escape(video.caption)}</figcaption></figure>")
                parts.append("</div>")
            else:
                parts.append(f"<p>{html.escape(item)}</p>")
        parts.append("</section>")
    parts.append("</body></html>")
    return "\n".join(parts) + "\n"


def _details(summary: str, lines: list[str]) -> str:
    body = "".join(f"<li>{html.escape(line)}</li>" for line in lines)
    return f"<details class=missing><summary>{html.escape(summary)}</summary><ul class=notes>{body}</ul></details>"


# A cell that starts with a digit or a dash is a number, a rate or a count: it never breaks
# across lines; words (names, notes, headers) wrap, so a table narrows to fit the page.
_NUMERIC_CELL = re.compile(r"^[-+\u2212\u2014]?\d|^\u2014$")


def _html_table(frame: pd.DataFrame) -> str:
    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in frame.columns)
    rows = []
    for values in frame.itertuples(index=False):
        cells = []
        for value in values:
            text = MISSING if value is None or (isinstance(value, float) and pd.isna(value)) else str(value)
            numeric = " class=n" if _NUMERIC_CELL.match(text) else ""
            cells.append(f"<td{numeric}>{html.escape(text)}</td>")
        rows.append("<tr>" + "".join(cells) + "</tr>")
    return f'<table class="data"><thead><tr>{head}</tr></thead><tbody>{"".join(rows)}</tbody></table>'


def to_json_text(value: object) -> str:
    return json.dumps(value, indent=2, sort_keys=False, default=str)


def _markdown_table(frame: pd.DataFrame) -> str:
    if frame.empty:
        return f"| |\n|---|\n| {MISSING} |"
    cleaned = frame.astype(str).apply(lambda col: col.str.replace("|", "\\|").str.replace("\n", "<br>"))
    return cleaned.to_markdown(index=False)


def _latex_escape(text: str) -> str:
    replacements = {"\\": r"\textbackslash{}", "&": r"\&", "%": r"\%", "$": r"\$", "#": r"\#",
                    "_": r"\_", "{": r"\{", "}": r"\}", "~": r"\textasciitilde{}", "^": r"\textasciicircum{}"}
    return "".join(replacements.get(ch, ch) for ch in text)


_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Helvetica,Arial,sans-serif;max-width:1200px;margin:2em auto;padding:0 1em;color:#222}
h1{font-size:1.6em}h2{border-bottom:2px solid #ddd;padding-bottom:.2em;margin-top:2em}h3{margin-bottom:.2em}
div.scroll{max-width:100%;overflow-x:auto;margin:.5em 0}
table.data{border-collapse:collapse;font-size:.82em}
table.data th,table.data td{border-bottom:1px solid #e3e3e3;padding:.25em .6em;text-align:left}
table.data td.n{white-space:nowrap}
table.data thead th{border-bottom:2px solid #999;background:#f6f6f6;vertical-align:bottom;min-width:4em}
h4{margin:.8em 0 .2em;font-size:.95em}
p.caption{color:#555;font-size:.9em;margin-top:0}ul.notes{color:#555;font-size:.85em}
figure{margin:1em 0}figure img{max-width:100%;border:1px solid #eee}figcaption{font-size:.85em;color:#555}
pre{background:#f6f6f6;padding:.8em;overflow-x:auto;font-size:.8em}nav ol{columns:2;font-size:.9em}
details.missing summary{cursor:pointer;color:#555;font-size:.9em}
div.videos{display:flex;flex-wrap:wrap;gap:1em}div.videos figure{margin:0;flex:1 1 420px;max-width:560px}
div.videos video{width:100%;border:1px solid #ddd;background:#000}
div.novideo{padding:3em 1em;background:#f3f3f3;color:#777;text-align:center}
"""
