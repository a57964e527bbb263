#!/usr/bin/env python3
"""Checks that the guide cannot drift from the sources (issue 65's tests).

  check_docs.py links SOURCE_ROOT
      every relative link in README.md, docs/ and bench/README.md resolves: the file exists and a
      #fragment names a heading of the Markdown file it points to (GitHub's anchors)
  check_docs.py tutorial PERF_BINARY TUTORIAL_MD
      every perf command in a fenced sh block names an existing subcommand and only options that
      its --help lists
  check_docs.py readme SOURCE_ROOT
      README.md is a front page: at most 1500 words, no dated history ("issue N", a date outside
      the results table)

Each prints what it checked and exits 1 naming every failure.
"""
import pathlib
import re
import shlex
import sys

# The CLI's help as check_option_pages.py reads it (one parser for both checks).
from check_option_pages import option_names, run_help, subcommands

LINK = re.compile(r"(?<!\!)\[[^\]]*\]\(([^)\s]+)\)|\!\[[^\]]*\]\(([^)\s]+)\)")
FENCE = re.compile(r"^```(\w*)\s*$")


def strip_code(text):
    """The text without fenced blocks and inline code, where links are not links."""
    out, fenced = [], False
    for line in text.splitlines():
        if FENCE.match(line.strip()) or line.strip().startswith("```"):
            fenced = not fenced
            out.append("")
            continue
        out.append("" if fenced else re.sub(r"`[^`]*`", "", line))
    return out


def slug(heading):
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces to hyphens."""
    s = heading.strip().lower()
    s = re.sub(r"[^\w\- ]", "", s)
    return s.replace(" ", "-")


def anchors(path):
    seen, result = {}, set()
    for line in strip_code(path.read_text(encoding="utf-8")):
        m = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if not m:
            continue
        base = slug(m.group(1))
        n = seen.get(base, 0)
        seen[base] = n + 1
        result.add(base if n == 0 else f"{base}-{n}")
    return result


def check_links(root):
    root = pathlib.Path(root)
    files = [f for f in [root / "README.md", root / "bench" / "README.md"] + sorted((root / "docs").rglob("*.md"))
             if f.exists()]
    failures, count = [], 0
    for md in files:
        if not md.exists():
            continue
        for lineno, line in enumerate(strip_code(md.read_text(encoding="utf-8")), 1):
            for m in LINK.finditer(line):
                target = m.group(1) or m.group(2)
                if re.match(r"^[a-z][a-z0-9+.-]*:", target):  # http:, mailto: ...: not relative
                    continue
                count += 1
                path_part, _, fragment = target.partition("#")
                dest = md if not path_part else (md.parent / path_part)
                where = f"{md.relative_to(root)}:{lineno}: {target}"
                if not dest.exists():
                    failures.append(f"{where}: no such file {dest.resolve().relative_to(root.resolve())}"
                                    if dest.resolve().is_relative_to(root.resolve()) else f"{where}: outside the tree")
                    continue
                if fragment and dest.suffix == ".md" and fragment not in anchors(dest):
                    failures.append(f"{where}: no heading with the anchor #{fragment} in {dest.name}")
    return failures, f"{count} relative links in {len(files)} files"


def check_tutorial(perf, tutorial):
    text = pathlib.Path(tutorial).read_text(encoding="utf-8")
    commands, failures = set(subcommands(run_help(perf, []))), []
    blocks = re.findall(r"^```sh\n(.*?)^```", text, re.M | re.S)
    checked = 0
    for block in blocks:
        for raw in block.replace("\\\n", " ").splitlines():
            line = raw.split("#", 1)[0].strip()
            if not line:
                continue
            words = shlex.split(line)
            if not words or not re.search(r"(^|/)perf$", words[0]):
                continue
            checked += 1
            if len(words) < 2 or words[1] not in commands:
                failures.append(f"{line}: '{words[1] if len(words) > 1 else ''}' is not a perf subcommand")
                continue
            listed = set(option_names(words[1], run_help(perf, [words[1]])))
            for w in words[2:]:
                name = w.split("=", 1)[0]
                if name.startswith("-") and name not in listed:
                    failures.append(f"{line}: perf {words[1]} --help lists no {name}")
    if checked == 0:
        failures.append(f"{tutorial}: no perf command in a fenced sh block")
    return failures, f"{checked} perf commands in {len(blocks)} sh blocks"


def check_readme(root):
    text = (pathlib.Path(root) / "README.md").read_text(encoding="utf-8")
    prose = "\n".join(strip_code(text))
    words = len(re.findall(r"\S+", re.sub(r"\]\([^)]*\)", "]", prose)))
    failures = []
    if words > 1500:
        failures.append(f"README.md: {words} words outside code and link targets, more than 1500")
    for lineno, line in enumerate(strip_code(text), 1):
        if re.search(r"\bissues? \d+", line, re.I):
            failures.append(f"README.md:{lineno}: names an issue: {line.strip()[:80]}")
        if re.search(r"\b20\d\d-\d\d-\d\d\b", line) and not line.lstrip().startswith("|"):
            failures.append(f"README.md:{lineno}: a date outside the results table: {line.strip()[:80]}")
    return failures, f"README.md: {words} words"


def main(argv):
    modes = {"links": (check_links, 1), "tutorial": (check_tutorial, 2), "readme": (check_readme, 1)}
    if len(argv) < 2 or argv[1] not in modes or len(argv) != 2 + modes[argv[1]][1]:
        print(__doc__, file=sys.stderr)
        return 2
    failures, summary = modes[argv[1]][0](*argv[2:])
    for f in failures:
        print(f"FAIL {f}")
    print(f"{argv[1]}: {summary}: {'ok' if not failures else f'{len(failures)} failures'}")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
