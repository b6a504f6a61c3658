"""The report page: plain HTML (no script), one file ``index.html`` with its figures beside
it as PNGs, linked by relative names so the directory can be moved or mailed as a whole.

A page is a list of sections; a section holds paragraphs, figures, tables, notes (what
the report could not show, and why) and findings (warnings a reader must see).
"""
from __future__ import annotations

import html
from dataclasses import dataclass, field
from pathlib import Path

from planecal.present.report.figures import Plot

STYLE = """
body { font-family: sans-serif; max-width: 1100px; margin: 1.5em auto; padding: 0 1em;
       color: #222; line-height: 1.4; }
h1 { font-size: 1.5em; border-bottom: 2px solid #444; padding-bottom: .2em; }
h2 { font-size: 1.2em; margin-top: 1.8em; border-bottom: 1px solid #bbb; }
figure { margin: 1em 0 1.5em 0; }
figure img { max-width: 100%; height: auto; border: 1px solid #ddd; }
figcaption { font-size: .9em; color: #444; margin-top: .3em; }
table { border-collapse: collapse; margin: .8em 0; font-size: .9em; }
th, td { border: 1px solid #ccc; padding: .2em .6em; text-align: right; }
th { background: #f0f0f0; }
td.l, th.l { text-align: left; }
.note { background: #fff8dc; border-left: 4px solid #e0b000; padding: .4em .8em; margin: .6em 0; }
.finding { background: #fdecea; border-left: 4px solid #d62728; padding: .4em .8em; margin: .4em 0; }
.ok { background: #eaf5ea; border-left: 4px solid #2ca02c; padding: .4em .8em; margin: .4em 0; }
code, .mono { font-family: monospace; }
"""


@dataclass
class Table:
    headers: list[str]
    rows: list[list]
    left: int = 1  # the first ``left`` columns are text, aligned left


@dataclass
class Section:
    title: str
    items: list = field(default_factory=list)

    def text(self, s: str) -> None:
        self.items.append(("p", s))

    def figure(self, plot: Plot | None) -> None:
        if plot is not None:
            self.items.append(("fig", plot))

    def table(self, headers, rows, left: int = 1) -> None:
        self.items.append(("table", Table(list(headers), [list(r) for r in rows], left)))

    def note(self, s: str) -> None:
        """Something the report does not show, and why."""
        self.items.append(("note", s))

    def finding(self, s: str, ok: bool = False) -> None:
        """A result a reader must not miss (a warning, or with ok a check that passed)."""
        self.items.append(("ok" if ok else "finding", s))


@dataclass
class Page:
    title: str
    subtitle: str = ""
    sections: list[Section] = field(default_factory=list)

    def section(self, title: str) -> Section:
        s = Section(title)
        self.sections.append(s)
        return s

    @property
    def plots(self) -> list[Plot]:
        return [it[1] for s in self.sections for it in s.items if it[0] == "fig"]

    def render(self) -> str:
        e = html.escape
        out = ["<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">',
               '<meta name="generator" content="planecal">',  # outputs.HTML_MARK
               f"<title>{e(self.title)}</title>", f"<style>{STYLE}</style>", "</head>", "<body>",
               f"<h1>{e(self.title)}</h1>"]
        if self.subtitle:
            out.append(f"<p>{e(self.subtitle)}</p>")
        if len(self.sections) > 2:
            out.append("<p>" + " · ".join(f'<a href="#s{i}">{e(s.title)}</a>'
                                         for i, s in enumerate(self.sections)) + "</p>")
        for i, s in enumerate(self.sections):
            out.append(f'<h2 id="s{i}">{e(s.title)}</h2>')
            for kind, item in s.items:
                if kind == "p":
                    out.append(f"<p>{e(item)}</p>")
                elif kind in ("note", "finding", "ok"):
                    out.append(f'<div class="{kind}">{e(item)}</div>')
                elif kind == "fig":
                    out.append(f'<figure><img src="{e(item.file)}" alt="{e(item.title)}">'
                               f"<figcaption><b>{e(item.title)}.</b> {e(item.caption)}"
                               f"</figcaption></figure>")
                elif kind == "table":
                    out.append(_table_html(item))
        out += ["</body>", "</html>", ""]
        return "\n".join(out)

    def write(self, out_dir: Path) -> Path:
        path = Path(out_dir) / "index.html"
        path.write_text(self.render(), encoding="utf-8")
        return path


def _table_html(t: Table) -> str:
    e = html.escape

    def cls(i):
        return ' class="l"' if i < t.left else ""
    rows = ["<table>", "<tr>" + "".join(f"<th{cls(i)}>{e(str(h))}</th>"
                                        for i, h in enumerate(t.headers)) + "</tr>"]
    for r in t.rows:
        rows.append("<tr>" + "".join(f"<td{cls(i)}>{e(str(c))}</td>" for i, c in enumerate(r))
                    + "</tr>")
    rows.append("</table>")
    return "\n".join(rows)
