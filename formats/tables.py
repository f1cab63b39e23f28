"""Tables as text: aligned plain-text columns for the terminal, Markdown for reports.

One formatter of each kind for every table sonarmap prints or writes (validate, evaluate,
regress, the run report, the batch summary).
"""

from __future__ import annotations

from collections.abc import Collection, Sequence

__all__ = ["markdown_table", "md_cell", "text_table"]


def text_table(
    header: Sequence[str] | None,
    rows: Sequence[Sequence[str]],
    *,
    right: Collection[int] = (),
    rule: bool = False,
) -> list[str]:
    """Lines of columns two spaces apart, each as wide as its widest cell (``right``:
    right-aligned column indices), trailing spaces removed. ``rule`` puts a line of dashes
    under the header, as wide as each column and, for the last, as its header."""
    table = [list(header), *map(list, rows)] if header is not None else list(map(list, rows))
    if not table:
        return []
    ncols = len(table[0])
    widths = [max(len(r[i]) for r in table) for i in range(ncols)]

    def line(cells: Sequence[str]) -> str:
        parts = [
            c.rjust(w) if i in right else c.ljust(w)
            for i, (c, w) in enumerate(zip(cells, widths, strict=True))
        ]
        return "  ".join(parts).rstrip()

    lines = [line(r) for r in table]
    if rule and header is not None:
        dashes = ["-" * w for w in widths[:-1]] + ["-" * len(header[-1])]
        lines.insert(1, "  ".join(dashes))
    return lines


def md_cell(text: str) -> str:
    """A Markdown table cell: backslashes and pipes escaped, newlines as spaces."""
    return text.replace("\\", "\\\\").replace("|", "\\|").replace("\n", " ")


def markdown_table(
    header: Sequence[str], rows: Sequence[Sequence[str]], *, right: Collection[int] = ()
) -> list[str]:
    """Lines of a Markdown table (``right``: right-aligned column indices)."""
    lines = ["| " + " | ".join(md_cell(h) for h in header) + " |"]
    lines.append("|" + "|".join(" --: " if i in right else " --- " for i in range(len(header))) + "|")
    lines += ["| " + " | ".join(md_cell(c) for c in r) + " |" for r in rows]
    return lines
