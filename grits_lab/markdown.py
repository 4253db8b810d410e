"""Markdown tables laid out from formatted cells: the results pages, `compare-runs` and
`compare-predictors` (the report's own tables go through pandas, `report/render.py`). Cells are
written as given: a `|` inside one is the caller's to escape."""

from __future__ import annotations


def markdown_table(header: list[str], rows: list[list[str]], right: int = 1) -> str:
    """A Markdown (GitHub) table of `header` and `rows` (each as long as the header, cells already
    formatted); columns from index `right` on are right-aligned. ValueError for a row of another
    length."""
    for row in rows:
        if len(row) != len(header):
            raise ValueError(f"a table row has {len(row)} cells, the header {len(header)}")
    align = ["---" if i < right else "---:" for i in range(len(header))]
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join(align) + "|"]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)
