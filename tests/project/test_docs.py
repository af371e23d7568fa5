"""The doc check: every command, link and repository path in README.md and docs/*.md must be real.

Conventions (docs/testing.md, "The doc check"):

* A command is a line of a ```` ```sh ```` block; a trailing backslash continues it, ``#`` starts a
  comment, ``[...]`` marks optional parts and ``a|b`` alternatives (usage-line notation). Other
  fenced blocks are not commands: ``text`` (output), ``yaml``, ``python``, ``json``, and ``bash``
  for a script file shown whole (each listed in ``SCRIPT_BLOCKS`` with its reason). An untagged
  block fails, so that no command hides in one.
* ``synth ...`` / ``reloc ...``: the subcommand path must exist and every option must be accepted by
  that subcommand, read from the CLIs' own argparse parsers (``build_parser()``), in-process.
  ``python -m MODULE`` / ``python SCRIPT``: the same against ``--help`` of the module (run once,
  cached), and pytest's options and ``-m`` markers (declared in pyproject.toml). ``make ARGS``:
  ``make -n ARGS`` succeeds. ``pip install '.[EXTRA]'``: EXTRA is an extra of pyproject.toml.
  Any other program must be listed in ``FOREIGN`` with the reason it is not checked.
* Repository paths in commands exist (globs match something), except what a command writes.
* Inline code in prose that starts with ``synth `` or ``reloc `` is checked as a command; a
  repository path or a ``synth.``/``reloc.``/``vrformats.`` module named in inline code exists.
* Relative links point to existing files, and their ``#anchors`` to headings there.

Nothing renders or runs: the whole check takes a few seconds.
"""

from __future__ import annotations

import argparse
import functools
import glob
import os
import re
import shlex
import subprocess
import sys
import tomllib
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]

# fenced blocks that are not commands a user types
LANGS = {"sh", "bash", "text", "yaml", "python", "json"}
# ```bash blocks: script files shown whole, keyed by (page, first line); not commands of this toolkit
SCRIPT_BLOCKS = {
    ("docs/external_relocalizers.md", "#!/usr/bin/env bash"):
        "run_ace.sh, a wrapper script around ACE (nianticlabs/ace, not installed here) that an experiment "
        "spec runs; its commands are ACE's",
}
# programs of other projects that appear in commands: not checked, and why
FOREIGN = {
    "ray": "Ray's own CLI (ray start/status/stop): it joins or inspects a cluster, which the check cannot start",
    "pip": "pip itself; only `pip install '.[EXTRA]'` is checked (the extra must exist in pyproject.toml)",
}
# options whose value is a file or folder a command writes: not required to exist
OUTPUT_OPTIONS = {"--out", "--out-dir", "--save-calibration", "--save", "--report", "--junit"}
# top-level folders and files of the repository: a path starting with one of these must exist
REPO_TOPS = ("render_jobs/", "scenes/", "models/", "docs/", "tools/", "tests/", "vrformats/", "synth/", "reloc/",
             ".ci/", "Makefile", "pyproject.toml")
PYTHONS = {"python", "python3", "python3.11", ".venv/bin/python", "$(VENV)/bin/python"}


# ---------------------------------------------------------------------------------------------
# reading the pages


@dataclass(frozen=True)
class Block:
    page: str
    line: int  # of the opening fence, 1-based
    lang: str
    lines: tuple[tuple[int, str], ...]


@dataclass(frozen=True)
class Command:
    page: str
    line: int
    text: str
    inline: bool = False

    @property
    def where(self) -> str:
        return f"{self.page}:{self.line}"


FENCE = re.compile(r"^\s*(`{3,}|~{3,})\s*([\w+-]*)\s*$")


def rel(p: Path) -> str:
    return p.relative_to(ROOT).as_posix()


@functools.cache
def parse_page(path: Path) -> tuple[tuple[Block, ...], str, tuple[tuple[int, str], ...]]:
    """The page's fenced blocks, its prose (fenced blocks blanked, line numbers kept) and prose lines."""
    blocks, prose = [], []
    lines = path.read_text().split("\n")
    i = 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            prose.append((i + 1, lines[i]))
            i += 1
            continue
        fence, lang, start = m.group(1), m.group(2), i
        body = []
        i += 1
        while i < len(lines) and not re.match(rf"^\s*{re.escape(fence[0])}{{{len(fence)},}}\s*$", lines[i]):
            body.append((i + 1, lines[i]))
            i += 1
        assert i < len(lines), f"{rel(path)}:{start + 1}: unclosed code fence"
        blocks.append(Block(rel(path), start + 1, lang, tuple(body)))
        prose.extend((n, "") for n, _ in body)
        prose.append((start + 1, ""))
        prose.append((i + 1, ""))
        i += 1
    prose.sort()
    text = "\n".join(t for _, t in prose)
    return tuple(blocks), text, tuple(prose)


CODE_SPAN = re.compile(r"(?<!`)(`+)(?!`)(.+?)(?<!`)\1(?!`)", re.DOTALL)


def code_spans(path: Path) -> list[tuple[int, str]]:
    """Inline code spans of the prose: (line, content)."""
    _, text, _ = parse_page(path)
    out = []
    for m in CODE_SPAN.finditer(text):
        line = text.count("\n", 0, m.start()) + 1
        out.append((line, m.group(2).strip()))
    return out


def block_commands(block: Block) -> list[Command]:
    cmds, buf, first = [], "", None
    for n, raw in block.lines:
        s = raw.rstrip()
        if first is None:
            first = n
        if s.endswith("\\"):
            buf += s[:-1] + " "
            continue
        buf += s
        if buf.strip() and not buf.strip().startswith("#"):
            cmds.append(Command(block.page, first, buf.strip()))
        buf, first = "", None
    assert not buf.strip(), f"{block.page}:{block.line}: a command ends with a line continuation"
    return cmds


def all_commands() -> list[Command]:
    cmds = []
    for p in PAGES:
        blocks, _, _ = parse_page(p)
        for b in blocks:
            if b.lang == "sh":
                cmds.extend(block_commands(b))
        for line, span in code_spans(p):
            s = span.replace("\\|", "|")
            if re.match(r"(synth|reloc)( |$)", s):
                cmds.append(Command(rel(p), line, s, inline=True))
    return cmds


COMMANDS = all_commands()


def words(cmd: Command) -> list[str]:
    try:
        return shlex.split(cmd.text.replace("\\|", "|"), comments=True)
    except ValueError as e:
        pytest.fail(f"{cmd.where}: cannot split {cmd.text!r}: {e}")


def bare(tok: str) -> str:
    """A usage-line token without its optional brackets."""
    return tok.strip("[]")


def options_of(toks: list[str]) -> list[str]:
    out = []
    for t in toks:
        t = bare(t)
        if re.fullmatch(r"--[A-Za-z0-9][\w-]*(=.*)?", t):
            out.append(t.split("=")[0])
        elif re.fullmatch(r"-[A-Za-z]", t):
            out.append(t)
    return out


# ---------------------------------------------------------------------------------------------
# the CLIs' parsers and other programs' help


@functools.cache
def parser(prog: str) -> argparse.ArgumentParser:
    if prog == "synth":
        from synth.cli import build_parser
    else:
        from reloc.cli import build_parser
    return build_parser()


def subparsers(p: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    out = {}
    for a in p._actions:
        if isinstance(a, argparse._SubParsersAction):
            out.update(a.choices)
    return out


def option_strings(p: argparse.ArgumentParser) -> set[str]:
    return {o for a in p._actions for o in a.option_strings}


def leaves(p: argparse.ArgumentParser) -> list[argparse.ArgumentParser]:
    subs = subparsers(p)
    return [p] if not subs else [leaf for s in subs.values() for leaf in leaves(s)]


def resolve(prog: str, toks: list[str]) -> list[tuple[str, argparse.ArgumentParser]]:
    """The parsers a command names: usage alternatives (``a|b``) and ``...`` give several."""
    found = []

    def walk(p, path, rest):
        subs = subparsers(p)
        if not subs or not rest or bare(rest[0]).startswith("-"):
            found.append((" ".join(path), p))
            return
        tok = bare(rest[0])
        if tok == "...":
            for leaf in leaves(p):
                found.append((" ".join(path + ["..."]), leaf))
            return
        for alt in tok.split("|"):
            if alt not in subs:
                raise LookupError(f"no subcommand {' '.join([prog, *path, alt])!r}; "
                                  f"{' '.join([prog, *path])} has: {', '.join(sorted(subs))}")
            walk(subs[alt], path + [alt], rest[1:])

    walk(parser(prog), [], toks)
    return found


@functools.cache
def help_text(*argv: str) -> str:
    r = subprocess.run([sys.executable, *argv, "--help"], cwd=ROOT, capture_output=True, text=True, check=False, timeout=120)
    assert r.returncode == 0, f"{' '.join(argv)} --help failed ({r.returncode}): {r.stderr[-800:]}"
    return r.stdout


@functools.cache
def pyproject() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())


def declared_markers() -> set[str]:
    return {m.split(":")[0].strip() for m in pyproject()["tool"]["pytest"]["ini_options"]["markers"]}


def module_file(dotted: str) -> Path | None:
    base = ROOT.joinpath(*dotted.split("."))
    for f in (base.with_suffix(".py"), base / "__init__.py", base / "__main__.py"):
        if f.is_file():
            return f
    return None


# ---------------------------------------------------------------------------------------------
# repository paths


PLACEHOLDER = re.compile(r"(^|/)[A-Z][A-Z0-9_]*(\.|/|$)|[<>{}$]|\.\.\.")


def is_repo_path(tok: str) -> bool:
    return tok.startswith(REPO_TOPS) and not PLACEHOLDER.search(tok)


def path_problem(tok: str) -> str | None:
    tok = tok.rstrip(".,;:)")
    if any(c in tok for c in "*?["):
        return None if glob.glob(str(ROOT / tok)) else f"{tok}: matches no file"
    return None if (ROOT / tok).exists() else f"{tok}: no such file or folder"


def command_paths(toks: list[str]) -> list[str]:
    out, skip = [], False
    for t in toks:
        t = bare(t)
        if skip:
            skip = False
            continue
        opt = t.split("=")[0]
        if opt in OUTPUT_OPTIONS:
            skip = "=" not in t
            continue
        for part in t.split("|"):
            v = part.split("=", 1)[1] if part.startswith("-") and "=" in part else part
            if is_repo_path(v):
                out.append(v)
    return out


# ---------------------------------------------------------------------------------------------
# checking one command


def strip_env(toks: list[str]) -> list[str]:
    while toks and re.fullmatch(r"[A-Z_][A-Z0-9_]*=.*", toks[0]):
        toks = toks[1:]
    return toks


def check_pytest(cmd: Command, args: list[str]) -> list[str]:
    problems = []
    text = help_text("-m", "pytest")
    for o in options_of(args):
        if not re.search(rf"(?<![\w-]){re.escape(o)}(?![\w-])", text):
            problems.append(f"pytest has no option {o}")
    for i, a in enumerate(args):
        if a == "-m" and i + 1 < len(args):
            names = set(re.findall(r"[A-Za-z_]\w*", args[i + 1])) - {"and", "or", "not"}
            for n in sorted(names - declared_markers()):
                problems.append(f"marker {n!r} is not declared in pyproject.toml")
    return problems


def check_command(cmd: Command) -> list[str]:
    toks = strip_env(words(cmd))
    if not toks:
        return []
    prog, rest = toks[0], toks[1:]
    problems = [f"repository path {p}" for p in (path_problem(t) for t in command_paths(rest)) if p]
    name = Path(prog).name if prog.endswith(("/synth", "/reloc")) else prog
    if name in ("synth", "reloc"):
        try:
            targets = resolve(name, rest)
        except LookupError as e:
            return problems + [str(e)]
        used = options_of(rest)
        for path, p in targets:
            known = option_strings(p)
            for o in used:
                if o not in known:
                    problems.append(f"`{name} {path}` has no option {o} (it has: {', '.join(sorted(known))})")
        return problems
    if prog in PYTHONS:
        if rest[:1] == ["-m"]:
            mod, args = rest[1], rest[2:]
            if mod == "pytest":
                return problems + check_pytest(cmd, args)
            f = module_file(mod)
            if f is None:
                return problems + [f"no module {mod}"]
            argv = ("-m", mod)
        else:
            script, args = rest[0], rest[1:]
            f = ROOT / script
            if not f.is_file():
                return problems + [f"no script {script}"]
            argv = (script,)
        if "argparse" not in f.read_text():
            return problems + [f"{rel(f)} has no argparse --help to check its options against"]
        text = help_text(*argv)
        sub = args[0] if args and not args[0].startswith("-") else None
        if sub and re.search(r"\{[\w,-]*\b" + re.escape(sub) + r"\b[\w,-]*\}", text):  # a subcommand: its own options
            text = help_text(*argv, sub)
        for o in options_of(args):
            if not re.search(rf"(?<![\w-]){re.escape(o)}(?![\w-])", text):
                problems.append(f"{' '.join(argv)} has no option {o}")
        return problems
    if prog == "make":
        r = subprocess.run(["make", "-n", *rest], cwd=ROOT, capture_output=True, text=True, check=False, timeout=60)
        if r.returncode != 0:
            problems.append(f"make -n {' '.join(rest)} failed: {r.stderr.strip()[-400:]}")
        for a in rest:
            if a.startswith("PYTEST_ARGS="):
                problems += check_pytest(cmd, shlex.split(a.split("=", 1)[1]))
        return problems
    if prog == "pip" and rest[:1] == ["install"] and any(re.fullmatch(r"\.\[[\w,-]+\]", a) for a in rest):
        extras = set(pyproject()["project"]["optional-dependencies"])
        for a in rest:
            m = re.fullmatch(r"\.\[([\w,-]+)\]", a)
            for e in (m.group(1).split(",") if m else []):
                if e not in extras:
                    problems.append(f"pyproject.toml has no extra [{e}] (it has: {', '.join(sorted(extras))})")
        return problems
    if prog.startswith("tools/") and prog.endswith(".sh"):  # the repository's own scripts: there and runnable
        f = ROOT / prog
        if not f.is_file() or not os.access(f, os.X_OK):
            problems.append(f"{prog}: no such executable script in the repository")
        elif f.read_text().count("Usage:") and len(rest) < 1:
            problems.append(f"{prog}: called without its arguments (see its Usage line)")
        return problems
    if prog in FOREIGN:
        return problems
    return problems + [f"unknown program {prog!r}: check it here, or list it in FOREIGN with the reason it is not checked"]


def test_commands():
    """Every command of every page (one test, every problem listed with its page and line)."""
    problems = []
    for cmd in COMMANDS:
        found = check_command(cmd)
        if found:
            problems.append(f"{cmd.where}: {cmd.text}\n    " + "\n    ".join(found))
    assert not problems, f"{len(problems)} of {len(COMMANDS)} documented commands are wrong:\n" + "\n".join(problems)


# ---------------------------------------------------------------------------------------------
# the blocks themselves


def test_blocks_are_tagged():
    problems, scripts_seen = [], set()
    for p in PAGES:
        for b in parse_page(p)[0]:
            if b.lang not in LANGS:
                problems.append(f"{b.page}:{b.line}: code block tagged {b.lang!r}; use one of {sorted(LANGS)}")
            elif b.lang == "bash":
                key = (b.page, b.lines[0][1].strip() if b.lines else "")
                if key not in SCRIPT_BLOCKS:
                    problems.append(f"{b.page}:{b.line}: a ```bash block is a script shown whole; list it in "
                                    f"SCRIPT_BLOCKS with the reason, or make it ```sh commands")
                scripts_seen.add(key)
            elif b.lang != "sh":
                for n, line in b.lines:
                    if b.lang == "text" and re.match(r"\s*(\$ )?(synth|reloc|make) [a-z-]", line):
                        problems.append(f"{b.page}:{n}: a command in a ```{b.lang} block (make it ```sh)")
    problems += [f"SCRIPT_BLOCKS lists {k}, which no page has any more" for k in SCRIPT_BLOCKS if k not in scripts_seen]
    assert not problems, "\n".join(problems)


def test_the_two_commands():
    """The README's two set-up commands, exactly (CI runs `make test` through .ci/run)."""
    blocks, _, _ = parse_page(ROOT / "README.md")
    cmds = [c.text.split("#")[0].strip() for b in blocks if b.lang == "sh" for c in block_commands(b)]
    assert "make demo" in cmds and "make test" in cmds
    assert "make test" in (ROOT / ".ci" / "run").read_text()
    for target in ("demo", "test"):
        r = subprocess.run(["make", "-n", target], cwd=ROOT, capture_output=True, text=True, check=False, timeout=60)
        assert r.returncode == 0, r.stderr


def test_commands_cover_every_cli_group():
    """Every command group of both CLIs appears in some checked command."""
    named = set()
    for c in COMMANDS:
        toks = strip_env(words(c))
        if toks and toks[0] in ("synth", "reloc") and len(toks) > 1:
            named.add((toks[0], bare(toks[1])))
    missing = [f"{prog} {g}" for prog in ("synth", "reloc") for g in subparsers(parser(prog)) if (prog, g) not in named]
    assert not missing, f"command groups no page shows: {missing}"


# ---------------------------------------------------------------------------------------------
# links, paths and module names in the prose


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


@functools.cache
def anchors(path: Path) -> set[str]:
    seen: dict[str, int] = {}
    out = set()
    for _, line in parse_page(path)[2]:
        m = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if m:
            s = slug(m.group(1))
            k = seen.get(s, 0)
            out.add(s if k == 0 else f"{s}-{k}")
            seen[s] = k + 1
    return out


LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")


def links() -> list[tuple[Path, int, str]]:
    out = []
    for p in PAGES:
        _, text, _ = parse_page(p)
        text = CODE_SPAN.sub(lambda m: " " * len(m.group(0)), text)
        for m in LINK.finditer(text):
            out.append((p, text.count("\n", 0, m.start()) + 1, m.group(1)))
    return out


LINKS = links()


def test_links():
    problems, n = [], 0
    for page, line, target in LINKS:
        if re.match(r"[a-z]+:", target):
            continue  # http:, https:, mailto:
        n += 1
        file, _, anchor = target.partition("#")
        dest = (page.parent / file).resolve() if file else page
        where = f"{rel(page)}:{line}: {target}"
        if not dest.exists():
            problems.append(f"{where}: no such file")
        elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            problems.append(f"{where}: no heading #{anchor} in {rel(dest)}")
    assert n > 0
    assert not problems, "\n".join(problems)


DOTTED = re.compile(r"(?<![\w.])((?:synth|reloc|vrformats)(?:\.[A-Za-z_]\w*)+)")


def module_problem(dotted: str) -> str | None:
    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        f = module_file(".".join(parts[:i]))
        if f is None:
            continue
        rest = parts[i:]
        if not rest:
            return None
        name = rest[0]
        src = f.read_text()
        if re.search(rf"^\s*(def|class)\s+{name}\b|^\s*{name}\s*(:[^=]*)?=|^\s*from \S+ import .*\b{name}\b", src, re.MULTILINE):
            return None
        if re.search(rf"^from \S+ import \([^)]*\b{name}\b", src, re.MULTILINE):  # a parenthesised import
            return None
        return f"{dotted}: {rel(f)} defines no {name}"
    return f"{dotted}: no such module"


def test_paths_and_modules_in_prose():
    problems = []
    for p in PAGES:
        lines = dict(parse_page(p)[2])
        for line, span in code_spans(p):
            span = span.replace("\\|", "|")
            where = f"{rel(p)}:{line}"
            for tok in command_paths([t.strip("()[],;:'\"") for t in span.split()]):
                msg = path_problem(tok)
                if msg:
                    problems.append(f"{where}: {msg}")
            for m in DOTTED.finditer(span):
                if re.search(r"\.(py|yaml|json|md|onnx|txt)$", m.group(1)):
                    continue
                msg = module_problem(m.group(1))
                if msg:
                    problems.append(f"{where}: {msg}")
        # table rows: `a/b/c.py`, `d.py` means a/b/d.py
        for n, line in lines.items():
            if not line.lstrip().startswith("|"):
                continue
            base = None
            for m in CODE_SPAN.finditer(line):
                tok = m.group(2).strip()
                if is_repo_path(tok) and "/" in tok:
                    base = tok.rsplit("/", 1)[0]
                elif base and re.fullmatch(r"[\w]+\.py", tok) and not (ROOT / base / tok).is_file():
                    problems.append(f"{rel(p)}:{n}: {base}/{tok}: no such file")
    assert not problems, "\n".join(problems)


def test_inventory():
    """What the check covered (printed with -s), so that a change in coverage shows."""
    block = sum(not c.inline for c in COMMANDS)
    inline = sum(c.inline for c in COMMANDS)
    print(f"\ndoc check: {len(PAGES)} pages, {block} commands in ```sh blocks, {inline} inline commands, "
          f"{len(LINKS)} links, {len(SCRIPT_BLOCKS)} script block(s) and {len(FOREIGN)} foreign program(s) "
          "listed as not checked")
    assert block >= 50 and len(LINKS) >= 40
