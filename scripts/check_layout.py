#!/usr/bin/env python3
"""The source tree's layout rules, checked on the checkout it lives in:
  - recon_cuda/ is read in wings, core < data < solve < backends < run: a file includes only
    headers of its own wing or of wings before it;
  - no source file over 500 lines and no function over 150 lines outside tests/.
Prints each violation and exits 1 if there is any; prints the wing include graph with --graph."""
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
WINGS = ["core", "data", "solve", "backends", "run"]
MAX_FILE_LINES = 500
MAX_FUNCTION_LINES = 150
SOURCE = re.compile(r"\.(h|cc|cu|cpp)$")
INCLUDE = re.compile(r'^\s*#\s*include\s+"recon_cuda/([a-z_]+)/')
CONTROL = re.compile(r"^\s*(if|for|while|switch|catch|do|else|return|namespace|struct|class|enum|union)\b")


FOLDERS = ["common", "workspace", "sfm_import", "recon_cuda", "export", "pipeline", "bench", "fuzz", "tests"]


def tracked_sources():
    """The sources in the project's own folders that git tracks (and those added but not yet
    committed); every source there where git is not available."""
    try:
        out = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard", "--", *FOLDERS],
                             cwd=ROOT, capture_output=True, text=True, check=True).stdout.split()
    except (OSError, subprocess.CalledProcessError):
        out = [str(p.relative_to(ROOT)) for f in FOLDERS for p in (ROOT / f).rglob("*")]
    return sorted(p for p in out if SOURCE.search(p) and (ROOT / p).is_file())


def strip_code(text):
    """Comments and string/char literals blanked, newlines kept (so braces in them do not count)."""
    out, i, n = [], 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            i = n if j < 0 else j
        elif text.startswith("/*", i):
            j = text.find("*/", i + 2)
            j = n if j < 0 else j + 2
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif text.startswith('R"', i):
            m = re.match(r'R"([^(]*)\(', text[i:])
            end = text.find(")" + (m.group(1) if m else "") + '"', i)
            j = n if end < 0 else end + len(m.group(1) if m else "") + 2
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif c in "\"'":
            j = i + 1
            while j < n and text[j] != c:
                j += 2 if text[j] == "\\" else 1
            out.append(c + " " * max(0, j - i - 1) + c)
            i = j + 1
        else:
            out.append(c)
            i += 1
    return "".join(out)


def long_functions(path, text):
    """(first line, length, name) of functions (free or member) longer than the limit."""
    code = strip_code(text)
    found, stack, header_start = [], [], 0
    line_of = [0] * (len(code) + 1)
    line = 1
    for k, ch in enumerate(code):
        line_of[k] = line
        if ch == "\n":
            line += 1
    for k, ch in enumerate(code):
        if ch == "{":
            header = code[header_start:k]
            is_function = (
                (not stack or stack[-1][1] in ("scope",))
                and re.search(r"\)\s*(const|noexcept|override|final|mutable|->[^;{]*|\s)*$", header)
                and not CONTROL.match(header.strip().split("\n")[-1] if header.strip() else "")
                and "=" not in header.split("(")[0]
            )
            kind = "function" if is_function else ("scope" if re.search(
                r"\b(namespace|struct|class|union)\b[^;()]*$|^\s*$|extern\s*$", header) else "block")
            name = re.sub(r"\s+", " ", header.strip())[-80:]
            stack.append((k, kind, name))
            header_start = k + 1
        elif ch == "}":
            if stack:
                start, kind, name = stack.pop()
                length = line_of[k] - line_of[start] + 1
                if kind == "function" and length > MAX_FUNCTION_LINES:
                    found.append((line_of[start], length, name))
            header_start = k + 1
        elif ch == ";":
            header_start = k + 1
    return found


def main():
    problems, edges = [], {}
    for rel in tracked_sources():
        text = (ROOT / rel).read_text(errors="replace")
        parts = Path(rel).parts
        if parts[0] == "recon_cuda" and len(parts) > 2 and parts[1] in WINGS:
            mine = WINGS.index(parts[1])
            for n, l in enumerate(text.split("\n"), 1):
                m = INCLUDE.match(l)
                if not m:
                    continue
                if m.group(1) not in WINGS:
                    problems.append(f"{rel}:{n}: includes recon_cuda/{m.group(1)}/, which is not a wing")
                    continue
                theirs = WINGS.index(m.group(1))
                edges.setdefault((parts[1], m.group(1)), 0)
                edges[(parts[1], m.group(1))] += 1
                if theirs > mine:
                    problems.append(f"{rel}:{n}: {parts[1]}/ includes the later wing {m.group(1)}/ ({l.strip()})")
        elif parts[0] == "recon_cuda" and len(parts) == 2:
            problems.append(f"{rel}: outside recon_cuda's wings ({', '.join(WINGS)})")
        if parts[0] == "tests":
            continue
        lines = text.count("\n") + (0 if text.endswith("\n") else 1)
        if lines > MAX_FILE_LINES:
            problems.append(f"{rel}: {lines} lines (at most {MAX_FILE_LINES})")
        for first, length, name in long_functions(rel, text):
            problems.append(f"{rel}:{first}: a function of {length} lines (at most {MAX_FUNCTION_LINES}): {name}")
    if "--graph" in sys.argv:
        print("recon_cuda wing includes (from -> to: count):")
        for (a, b), c in sorted(edges.items(), key=lambda e: (WINGS.index(e[0][0]), WINGS.index(e[0][1]))):
            print(f"  {a:9s} -> {b:9s} {c}")
    for p in problems:
        print(p)
    print(f"layout: {len(problems)} problem(s)")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
