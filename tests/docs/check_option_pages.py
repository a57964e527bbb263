#!/usr/bin/env python3
"""Checks that docs/commands/ documents every command and option of the `perf` CLI.

Usage: check_option_pages.py PERF_BINARY DOCS_DIR

For every subcommand that `PERF_BINARY --help` lists, runs `PERF_BINARY <command> --help` and
parses the names of its options (long and short: `-j,--threads` gives `-j` and `--threads`) and
positional arguments (`workspace`). The page DOCS_DIR/commands/<command>.md must exist and mention
each name literally in backticks: a code span that is the name, or starts with it followed by a
space or `=` (`--max-size`, `--max-size PX`, `-j`). Fenced code blocks do not count. The index
DOCS_DIR/commands/README.md must exist and link every page, and a page for a command the
binary no longer has is an error too.

Exit 0 with a one-line summary when everything is documented; exit 1 listing each missing page,
link and option (with the page it should be on); exit 2 when the binary cannot be run or its
help cannot be parsed. Standard library only.
"""

import os
import re
import subprocess
import sys

HELP_TIMEOUT_S = 60

# A line that starts a section of CLI11's help: "Options:", "Positionals:", "Subcommands:".
SECTION_RE = re.compile(r"^([A-Z][A-Za-z ]*):\s*$")
# An entry of a section: two spaces, then the entry's first token (names, no spaces).
ENTRY_RE = re.compile(r"^  (\S+)")
# CLI11 shows a flag's default or its negation after the name: `--no-second-pass{false}`.
BRACES_RE = re.compile(r"\{[^}]*\}")
# A positional's or an option's name.
NAME_RE = re.compile(r"^(--?[A-Za-z0-9][A-Za-z0-9_-]*|[A-Za-z_][A-Za-z0-9_-]*)$")
# Inline code spans (one or more backticks, the same number to close), on one line.
CODE_SPAN_RE = re.compile(r"(`+)([^`\n]+?)\1")


class HelpError(Exception):
    """The binary's help could not be run or parsed."""


def run_help(perf, args):
    command = [perf] + args + ["--help"]
    try:
        done = subprocess.run(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              universal_newlines=True, timeout=HELP_TIMEOUT_S, check=False)
    except (OSError, subprocess.TimeoutExpired) as e:
        raise HelpError("cannot run %s: %s" % (" ".join(command), e))
    if done.returncode != 0:
        raise HelpError("%s exited with %d: %s" % (" ".join(command), done.returncode, done.stderr.strip()))
    return done.stdout


def sections(help_text):
    """{section name: [first token of each entry]} of a CLI11 help text."""
    found = {}
    current = None
    for line in help_text.splitlines():
        m = SECTION_RE.match(line)
        if m:
            current = found.setdefault(m.group(1), [])
            continue
        if current is None:
            continue
        m = ENTRY_RE.match(line)
        if m:  # deeper-indented lines continue the entry before
            current.append(m.group(1))
    return found


def subcommands(help_text):
    names = sections(help_text).get("Subcommands", [])
    if not names:
        raise HelpError("`perf --help` lists no subcommands (no \"Subcommands:\" section)")
    for name in names:
        if not NAME_RE.match(name) or name.startswith("-"):
            raise HelpError("cannot parse the subcommand %r in `perf --help`" % name)
    return names


def option_names(command, help_text):
    """The names a page must mention: every option's long and short names, every positional."""
    found = sections(help_text)
    if "Options" not in found:
        raise HelpError("`perf %s --help` has no \"Options:\" section" % command)
    names = []
    for token in found.get("Positionals", []):
        if not NAME_RE.match(token):
            raise HelpError("cannot parse the positional %r in `perf %s --help`" % (token, command))
        names.append(token)
    for token in found["Options"]:
        for name in BRACES_RE.sub("", token).split(","):
            if not name.startswith("-") or not NAME_RE.match(name):
                raise HelpError("cannot parse the option %r in `perf %s --help`" % (token, command))
            names.append(name)
    return names


def without_fences(markdown):
    """The text outside fenced code blocks (``` or ~~~)."""
    kept = []
    fence = None
    for line in markdown.splitlines():
        stripped = line.lstrip()
        if fence is None and (stripped.startswith("```") or stripped.startswith("~~~")):
            fence = stripped[:3]
            continue
        if fence is not None:
            if stripped.startswith(fence):
                fence = None
            continue
        kept.append(line)
    return "\n".join(kept)


def code_spans(markdown):
    return [m.group(2).strip() for m in CODE_SPAN_RE.finditer(without_fences(markdown))]


def mentions(spans, name):
    for span in spans:
        if span == name or span.startswith(name + " ") or span.startswith(name + "="):
            return True
    return False


def read(path):
    with open(path, encoding="utf-8") as f:
        return f.read()


def check(perf, docs):
    """The problems found, one line each, and the counts for the summary."""
    problems = []
    pages_dir = os.path.join(docs, "commands")
    commands = subcommands(run_help(perf, []))
    checked = 0
    for command in commands:
        names = option_names(command, run_help(perf, [command]))
        page = os.path.join(pages_dir, command + ".md")
        if not os.path.isfile(page):
            problems.append("%s: missing: `perf %s` has no page (it should document %d options: %s)"
                            % (page, command, len(names), " ".join(names)))
            continue
        spans = code_spans(read(page))
        for name in names:
            checked += 1
            if not mentions(spans, name):
                problems.append("%s: `%s` of `perf %s --help` is not mentioned in backticks"
                                % (page, name, command))

    index = os.path.join(pages_dir, "README.md")
    if not os.path.isfile(index):
        problems.append("%s: missing: the index of the command pages" % index)
    else:
        text = read(index)
        for command in commands:
            if not re.search(r"\]\(\s*(\./)?%s\.md\s*\)" % re.escape(command), text):
                problems.append("%s: no link to %s.md (`perf %s`)" % (index, command, command))

    if os.path.isdir(pages_dir):
        for entry in sorted(os.listdir(pages_dir)):
            stem, ext = os.path.splitext(entry)
            if ext == ".md" and entry != "README.md" and stem not in commands:
                problems.append("%s: a page for `perf %s`, which `perf --help` does not list"
                                % (os.path.join(pages_dir, entry), stem))
    return problems, len(commands), checked


def main(argv):
    if len(argv) != 3:
        sys.stderr.write("usage: %s PERF_BINARY DOCS_DIR\n" % os.path.basename(argv[0]))
        return 2
    perf, docs = argv[1], argv[2]
    if not os.path.isdir(docs):
        sys.stderr.write("check_option_pages: %s is not a folder\n" % docs)
        return 2
    try:
        problems, commands, names = check(perf, docs)
    except HelpError as e:
        sys.stderr.write("check_option_pages: %s\n" % e)
        return 2
    if problems:
        for line in problems:
            print(line)
        print("check_option_pages: FAILED: %d problem(s); document each option on its command's page "
              "in backticks, e.g. `--max-size`" % len(problems))
        return 1
    print("check_option_pages: ok: %d commands, %d option and argument names, each on its page in %s"
          % (commands, names, os.path.join(docs, "commands")))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
