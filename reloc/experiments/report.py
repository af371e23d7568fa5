"""The experiment report: everything about one experiment results directory in one place.

``write_report(results_dir)`` writes ``report.md`` and ``report.html`` next to ``results.json``
(the ``videoreloc-experiment/1`` schema): title and experiment name, the evaluation protocol in
short, the design (query tours) and methods, the tables that ``reloc/tables.py`` wrote
(``tables/main.md``, ``factors.md``, ``units.md``, ``ablation.md``: the paper's Tables I-IV, then
any others), the recall of every method on every tour (with its 95 % interval), the results of
the last ``reloc check`` on the folder (``results.json``'s ``checks``, which ``reloc check`` writes and
after which it rewrites the report; a rerun of the experiment drops them with the results they judged), the plots that ``reloc/plots.py`` wrote (recall bars, then one
figure per tour, each a link to the full-size image), the timings, and what produced the results:
the code's commit (or the package version when installed), the machine (CPU model, cores) and the
library versions (``results.json``'s ``environment``, recorded by the run; a folder without it
gets this machine's, said so).

The markdown is the source; the HTML is converted from it by the small converter here
(``markdown_to_html``: headings, paragraphs, bullet lists, images on a line of their own and
pipe tables, with ``**bold**`` and ``code`` inline). All text is HTML-escaped; images are
referenced by path relative to the results directory, so the report moves with the directory.
Both files are written atomically.
"""

from __future__ import annotations

import html
import math
import re
from pathlib import Path

from vrformats.atomic import write_text_atomic

from .tables import EXTRA_TABLES, PAPER_TABLES, read_results, table_title

__all__ = ["write_report", "build_markdown", "markdown_to_html", "table_to_html", "split_row", "TABLE_ORDER"]

# (file stem under tables/, heading): the paper's tables in its order, numbered and titled as there
TABLE_ORDER = tuple((key, table_title(key)) for key in PAPER_TABLES) + tuple(
    (key, title) for key, (_, title) in EXTRA_TABLES.items())

PROTOCOL = [
    "Recall at 1 m/10\u00b0 (and at 0.25 m/5\u00b0) counts **all** ground-truth frames of the query tours: "
    "a frame without a returned pose is a failure. Position error is the distance of the camera centres, "
    "rotation error the angle of `R_gt^T R_est`. Median errors are taken over the returned poses only; "
    "coverage is the fraction of frames that have a pose.",
    "*Causal* poses are emitted as the frames arrive, from past frames only; *clip closure* re-estimates "
    "the frames of a clip once the clip is closed, with the whole clip.",
    "Rows marked \u2020 are clip-rigid controls: the method's poses combined with VideoReloc's clip partition "
    "and odometry, each clip placed as one rigid whole.",
]

CSS = """
body { font-family: -apple-system, "Segoe UI", Helvetica, Arial, sans-serif; max-width: 1200px; margin: 2em auto;
       padding: 0 1em; color: #222; line-height: 1.45; }
h1 { border-bottom: 2px solid #444; padding-bottom: .2em; }
h2 { border-bottom: 1px solid #bbb; padding-bottom: .15em; margin-top: 1.8em; }
table { border-collapse: collapse; margin: .8em 0; font-size: 0.92em; }
th, td { border: 1px solid #ccc; padding: .25em .6em; }
th { background: #f0f0f0; }
tbody tr:nth-child(even) { background: #fafafa; }
code { background: #f3f3f3; padding: 0 .2em; border-radius: 3px; }
figure { margin: 1em 0; }
figure img { max-width: 100%; border: 1px solid #ddd; }
td.fail { color: #b00; font-weight: bold; }
figcaption { font-size: 0.9em; color: #555; }
""".strip()


# --------------------------------------------------------------------------------------------
# markdown -> HTML (the subset this report and reloc/tables.py write)

_SEP_CELL = re.compile(r"^:?-+:?$")
_IMAGE = re.compile(r"^!\[(?P<alt>[^\]]*)\]\((?P<src>[^)\s]+)\)$")
_HEADING = re.compile(r"^(?P<level>#{1,6})\s+(?P<text>.*?)\s*#*\s*$")
_LIST = re.compile(r"^\s*[-*+]\s+(?P<text>.*)$")



def esc(text) -> str:
    return html.escape(str(text), quote=True)


def _inline(text: str) -> str:
    """Escaped text with `code`, **bold** and *italics*."""
    parts = re.split(r"(`[^`]+`)", text)
    out = []
    for p in parts:
        if len(p) >= 2 and p.startswith("`") and p.endswith("`"):
            out.append(f"<code>{esc(p[1:-1])}</code>")
            continue
        s = esc(p)
        s = re.sub(r"\*\*(.+?)\*\*", r"<strong>\1</strong>", s)
        s = re.sub(r"(?<![\w*])\*(?!\s)([^*]+?)(?<!\s)\*(?![\w*])", r"<em>\1</em>", s)
        out.append(s)
    return "".join(out)


def split_row(line: str) -> list[str]:
    """Cells of a pipe-table line ``| a | b |`` (``\\|`` is a literal bar), stripped."""
    s = line.strip()
    if s.startswith("|"):
        s = s[1:]
    if s.endswith("|") and not s.endswith("\\|"):
        s = s[:-1]
    return [c.strip().replace("\\|", "|") for c in re.split(r"(?<!\\)\|", s)]


def _is_separator(cells: list[str]) -> bool:
    return bool(cells) and all(_SEP_CELL.match(c.replace(" ", "")) for c in cells)


def table_to_html(lines: list[str]) -> str:
    """A pipe table (header, ``|---|`` line, body rows) as an HTML table; alignment from the colons."""
    rows = [split_row(ln) for ln in lines if ln.strip()]
    if not rows:
        return ""
    header, align = None, []
    if len(rows) >= 2 and _is_separator(rows[1]):
        header, sep, body = rows[0], rows[1], rows[2:]
        for c in sep:
            c = c.replace(" ", "")
            align.append("center" if c.startswith(":") and c.endswith(":") else "right" if c.endswith(":")
                         else "left" if c.startswith(":") else None)
    else:
        body = [r for r in rows if not _is_separator(r)]
    ncol = max(len(r) for r in ([header] if header else []) + body) if (header or body) else 0

    def cell(tag: str, k: int, text: str) -> str:
        a = align[k] if k < len(align) else None
        style = f' style="text-align:{a}"' if a else ""
        return f"<{tag}{style}>{_inline(text)}</{tag}>"

    out = ["<table>"]
    if header:
        cells = header + [""] * (ncol - len(header))
        out.append("<thead><tr>" + "".join(cell("th", k, c) for k, c in enumerate(cells)) + "</tr></thead>")
    out.append("<tbody>")
    for r in body:
        cells = r + [""] * (ncol - len(r))
        out.append("<tr>" + "".join(cell("td", k, c) for k, c in enumerate(cells)) + "</tr>")
    out.append("</tbody></table>")
    return "\n".join(out)


def markdown_to_html(text: str) -> str:
    """HTML body for the markdown subset: headings, paragraphs, lists, images, pipe tables."""
    lines = text.splitlines()
    out: list[str] = []
    para: list[str] = []
    items: list[str] = []

    def flush():
        if para:
            out.append("<p>" + _inline(" ".join(s.strip() for s in para)) + "</p>")
            para.clear()
        if items:
            out.append("<ul>\n" + "\n".join(f"<li>{_inline(t)}</li>" for t in items) + "\n</ul>")
            items.clear()

    i = 0
    while i < len(lines):
        ln = lines[i]
        s = ln.strip()
        if not s:
            flush()
            i += 1
            continue
        if s.startswith("|"):
            flush()
            j = i
            while j < len(lines) and lines[j].strip().startswith("|"):
                j += 1
            out.append(table_to_html(lines[i:j]))
            i = j
            continue
        m = _HEADING.match(s)
        if m:
            flush()
            n = len(m.group("level"))
            out.append(f"<h{n}>{_inline(m.group('text'))}</h{n}>")
            i += 1
            continue
        m = _IMAGE.match(s)
        if m:
            flush()
            alt = m.group("alt")
            src = esc(m.group("src"))  # the image links to itself: full size, whatever the page's width
            out.append(f'<figure><a href="{src}"><img src="{src}" alt="{esc(alt)}"></a>'
                       f"<figcaption>{_inline(alt)}</figcaption></figure>")
            i += 1
            continue
        m = _LIST.match(ln)
        if m and not para:
            items.append(m.group("text"))
            i += 1
            continue
        if items:  # a continuation line of the last item
            items[-1] += " " + s
        else:
            para.append(s)
        i += 1
    flush()
    return "\n".join(out)


def html_document(title: str, body: str) -> str:
    return ("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
            f"<title>{esc(title)}</title>\n<style>\n{CSS}\n</style>\n</head>\n<body>\n{body}\n</body>\n</html>\n")


# --------------------------------------------------------------------------------------------
# the report


def _md_cell(v) -> str:
    return str(v).replace("|", "\\|").replace("\n", " ")


def _md_table(header: list[str], rows: list[list]) -> str:
    lines = ["| " + " | ".join(_md_cell(h) for h in header) + " |",
             "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(_md_cell(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


def _demote(text: str, by: int = 2) -> str:
    """Headings of an included file pushed ``by`` levels down (at most level 6)."""
    def sub(m):
        return "#" * min(6, len(m.group(1)) + by) + " "
    return re.sub(r"^(#{1,6})\s+", sub, text, flags=re.M)


def _seconds(v) -> str:
    if v is None or isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        return "\u2014"
    return f"{v:.1f}" + (f" ({v / 60:.1f} min)" if v >= 120 else "")


def _table_files(results_dir: Path) -> list[tuple[str, Path]]:
    tdir = results_dir / "tables"
    out = [(heading, tdir / f"{name}.md") for name, heading in TABLE_ORDER if (tdir / f"{name}.md").is_file()]
    known = {f"{name}.md" for name, _ in TABLE_ORDER}
    if tdir.is_dir():
        out += [(p.stem.replace("_", " ").capitalize(), p) for p in sorted(tdir.glob("*.md")) if p.name not in known]
    return out


def _plot_files(results_dir: Path, results: dict) -> list[tuple[str, Path]]:
    from .plots import tour_png_name

    pdir = results_dir / "plots"
    cands = [("Recall at 1 m/10\u00b0 by lighting and layout change", pdir / "recall_bars.png")]
    for tname, tinfo in (results.get("tours") or {}).items():
        bits = [str(tinfo.get(k)) for k in ("layout", "lighting") if isinstance(tinfo, dict) and tinfo.get(k) is not None]
        if isinstance(tinfo, dict) and "rearranged" in tinfo:
            bits.append("rearranged" if tinfo["rearranged"] else "unchanged")
        cands.append((f"Tour {tname}" + (f" ({', '.join(bits)})" if bits else ""), pdir / tour_png_name(tname)))
    out = [(cap, p) for cap, p in cands if p.is_file()]
    seen = {p.name for _, p in cands}
    if pdir.is_dir():
        out += [(p.stem.replace("_", " "), p) for p in sorted(pdir.glob("*.png"))
                if p.name not in seen and not p.name.startswith(".")]
    return out


def _pct(v) -> str:
    return "\u2014" if not _is_number(v) else f"{100 * v:.1f}%"


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _per_tour_section(results: dict) -> list[str]:
    """Every table row's recall at 1 m/10 deg on every query tour, with its 95 % interval."""
    tours = results.get("tours") or {}
    rows = [r for r in (results.get("rows") or []) if isinstance(r, dict)]
    methods = results.get("methods") or {}
    if not tours or not rows:
        return []
    from .plots import row_label

    body = []
    for tname in tours:
        for row in rows:
            try:
                mode = methods[row["method"]]["modes"][row["mode"]]
            except (KeyError, TypeError):
                continue
            t = (mode.get("tours") or {}).get(tname) or {}
            iv = ((mode.get("intervals") or {}).get("tours") or {}).get(tname) or {}
            iv = iv.get("recall_1m_10deg") if isinstance(iv, dict) else None
            interval = (f"{100 * iv[0]:.1f}\u2013{100 * iv[1]:.1f}%" if isinstance(iv, list) and len(iv) == 2
                        and all(_is_number(x) for x in iv) else "\u2014")
            frames = t.get("frames", "")
            body.append([tname, row_label(row), _pct(t.get("recall_1m_10deg")), interval, _pct(t.get("coverage")),
                         frames])
    if not body:
        return []
    return ["## Recall per tour", "", "Recall at 1 m/10\u00b0 of every method on every query tour, over the frames "
            "it is scored on (frames), with its 95 % interval (\u2014: none).", "",
            _md_table(["tour", "method", "recall 1 m/10\u00b0", "95 % interval", "coverage", "frames"], body), ""]


def _checks_section(results: dict, results_dir: Path) -> list[str]:
    """The last ``reloc check``'s results (``results.json``'s ``checks``), or how to add them."""
    md = ["## Checks", ""]
    doc = results.get("checks")
    rows = doc.get("rows") if isinstance(doc, dict) else None
    if not isinstance(rows, list) or not rows:
        return md + [f"No checks were run on these results: `reloc check CHECKS.yaml {results_dir}` runs them and "
                     "adds them here.", ""]

    def num(v):
        return "\u2014" if not _is_number(v) else f"{v:.4g}"

    body = []
    for r in rows:
        if not isinstance(r, dict):
            continue
        iv = r.get("interval")
        ivs = (f"[{iv[0]:.3g}, {iv[1]:.3g}]" + (" (difference)" if r.get("interval_of") == "difference" else "")
               if isinstance(iv, list) and len(iv) == 2 and all(_is_number(x) for x in iv) else "\u2014")
        result = "pass" if r.get("passed") else f"**FAIL** ({r.get('why') or 'false'})"
        body.append([r.get("check", ""), f"`{r.get('expression', '')}`", num(r.get("value")), num(r.get("against")),
                     ivs, result])
    n_fail = sum(1 for r in rows if isinstance(r, dict) and not r.get("passed"))
    return md + [f"`reloc check {doc.get('file', '?')}`: {len(body) - n_fail} passed, {n_fail} failed.", "",
                 _md_table(["check", "expression", "value", "against", "interval", "result"], body), ""]


def _environment_section(results: dict) -> list[str]:
    """What produced the results: code, machine, libraries (recorded by the run, else this machine's)."""
    from vrformats.environment import describe, environment

    env = results.get("environment")
    note = ""
    if not isinstance(env, dict):
        env = environment()
        note = " (not recorded with the results: this is the machine and code that wrote the report)"
    return ["## Produced by", "", f"What ran the experiment{note}:", "",
            *[f"- {what}: {value}" for what, value in describe(env)], ""]


def build_markdown(results_dir, results: dict) -> str:
    """The report as markdown (image paths relative to ``results_dir``)."""
    results_dir = Path(results_dir)
    name = results.get("name") or results_dir.name
    tours = results.get("tours") or {}
    methods = results.get("methods") or {}
    md: list[str] = [f"# VideoReloc experiment report: {name}", ""]
    facts = [f"Experiment: `{name}`"]
    if results.get("spec"):
        facts.append(f"Spec: `{results['spec']}`")
    if results.get("map"):
        facts.append(f"Map: `{results['map']}`")
    n_frames = sum(int(t.get("frames") or 0) for t in tours.values() if isinstance(t, dict))
    facts.append(f"Query tours: {len(tours)} ({n_frames} frames)")
    facts.append(f"Results directory: `{results_dir}`")
    md += [f"- {f}" for f in facts] + [""]

    md += ["## Protocol", ""]
    for p in PROTOCOL:
        md += [p, ""]

    if tours:
        md += ["## Query tours", ""]
        rows = []
        for tname, t in tours.items():
            t = t if isinstance(t, dict) else {}
            change = "" if "rearranged" not in t else ("rearranged" if t["rearranged"] else "unchanged")
            rows.append([tname, t.get("layout", ""), t.get("lighting", ""), change, t.get("sensor", "ideal"),
                         t.get("frames", ""), "" if t.get("fps") is None else f"{t['fps']:g}"])
        md += [_md_table(["tour", "layout", "lighting", "layout change", "sensor", "frames", "fps"], rows), ""]

    if methods:
        md += ["## Methods", ""]
        rows = []
        for m, info in methods.items():
            info = info if isinstance(info, dict) else {}
            b = info.get("map_bytes")
            size = f"{b / 1024:.1f} KiB" if isinstance(b, (int, float)) and not isinstance(b, bool) else ""
            rows.append([m, info.get("label", ""), info.get("primary", ""), ", ".join(info.get("modes") or {}), size])
        md += [_md_table(["method", "label", "primary mode", "modes", "map size"], rows), ""]

    iv = results.get("intervals")
    if isinstance(iv, dict) and iv.get("segments"):
        ref = results.get("reference_sensor", "ideal")
        n_ref = sum(1 for t in tours.values() if isinstance(t, dict) and t.get("sensor", "ideal") == ref)
        st = iv.get("settings") or {}
        md += ["## Uncertainty", "", str(iv.get("note", "")), ""]
        md += [_md_table(["figure", "independent units it rests on"], [
            ["pooled recall and coverage (Table I)", " + ".join(f"{n} segments of path {p}" for p, n in
                                                                iv["segments"].items()) + f", each seen in {n_ref} tours"],
            ["a lighting or layout column (Table II)", "the same segments, seen in that column's tours"],
            ["ΔL, ΔR, kept, comparisons in checks", "the same segments, paired"],
            ["one tour", f"its segments of {st.get('segment_frames', '?')} frames"]]), ""]
        reps = results.get("replicates")
        if isinstance(reps, dict) and reps.get("count", 1) > 1:
            md += [f"Replicates: {reps['count']} runs of the experiment with reseeded random parts; Table I gives the "
                   "range of each row's recall across them.", ""]

    md += ["## Tables", ""]
    tables = _table_files(results_dir)
    if not tables:
        md += ["No tables were found under `tables/`.", ""]
    for heading, path in tables:
        md += [f"### {heading}", "", _demote(path.read_text().strip(), by=3), ""]

    md += _per_tour_section(results)
    md += _checks_section(results, results_dir)

    md += ["## Plots", ""]
    plots = _plot_files(results_dir, results)
    if not plots:
        md += ["No plots were found under `plots/`.", ""]
    for caption, path in plots:
        md += [f"### {caption}", "", f"![{caption}]({path.relative_to(results_dir).as_posix()})", ""]

    secs = results.get("seconds")
    if isinstance(secs, dict) and secs:
        md += ["## Timings", ""]
        rows = [[k, _seconds(v)] for k, v in secs.items()]
        md += [_md_table(["step", "seconds"], rows), "", "\u2014: no time recorded.", ""]

    md += _environment_section(results)

    degenerate = results.get("degenerate_frames")
    if degenerate:
        md += ["## Degenerate frames", "", "Frames without usable depth, or without the RGB the detector reads, as "
               "VideoReloc's runs counted them (a tour with more than odometry.max_degenerate_fraction of them fails):", ""]
        md += [_md_table(["tour", "frames", "no usable depth", "no RGB", "first"],
                         [[k, d["frames"], d["no_usable_depth"], d["no_rgb"], ", ".join(map(str, d["first"][:5]))]
                          for k, d in degenerate.items()]), ""]
    failed = results.get("failed")
    if failed:
        md += ["## Failed runs", "", "These runs failed or were skipped; their frames count as failures.", ""]
        items = failed.items() if isinstance(failed, dict) else ((str(x), "") for x in failed)
        md += [f"- `{k}`" + (f": {str(v).splitlines()[0] if str(v) else ''}" if v else "") for k, v in items] + [""]
    return "\n".join(md).rstrip() + "\n"


def write_report(results_dir) -> tuple[Path, Path]:
    """Write ``report.html`` and ``report.md`` into ``results_dir``; returns (html_path, md_path)."""
    results_dir = Path(results_dir)
    results = read_results(results_dir)
    md = build_markdown(results_dir, results)
    name = results.get("name") or results_dir.name
    md_path = write_text_atomic(results_dir / "report.md", md)
    html_path = write_text_atomic(results_dir / "report.html",
                                  html_document(f"VideoReloc experiment report: {name}", markdown_to_html(md)))
    return html_path, md_path
