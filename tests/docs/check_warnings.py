#!/usr/bin/env python3
"""Checks that docs/troubleshooting.md names every warning PERF prints.

Usage: check_warnings.py SOURCE_ROOT TROUBLESHOOTING_MD

Collects the warnings from PERF's C++ sources (tests, fuzzers, benchmarks and build folders
aside) in the styles they are written in:

  1. a string literal that prints "warning: " followed by text of its own:
       Say("import: warning: the new scene.json ..." + dropped + ...)
       std::cerr << "perf view: warning: listening on " << host << ...
       Report(options, StrCat("sfm: warning: only ", n, " of ", ...))
  2. the message a function named ...Warning returns (GhostGroup::Warning,
     LargeCorrectionsWarning, CutOffWarning, PhotoFits::Warning): each `return` with text;
  3. a message assigned (= or +=) to a variable or field named ...warning (choice.warning = ...);
  4. a message pushed into a vector named ...warnings (r->warnings.push_back(StrCat(...))).

A print of "warning: " followed only by a variable (Say("warning: " + w)) has no text of its
own: its texts are the ones styles 2-4 find.

Each message's key is its leading literal text: the literal fragments from the first one on,
whitespace collapsed and separators (": ", ", ") trimmed, until they hold at least 3 words and
16 characters, and at most 8 words (StrCat("skipped ", n, " images missing on disk: ", list)
gives "skipped ... images missing on disk"). A fragment chosen by a ternary between two
literals ("training photo fits" / "training photos fit") may appear in either form; the two
branches of `c ? StrCat(...) : "..."` are two messages. The page
must hold the fragments in order, at most 60 characters apart and not across a heading (where a
heading writes the variable part as N, NAME, DIR...), ignoring case, backticks and emphasis.
Exit 1 naming file:line and the key of each warning the page lacks; exit 0 printing how many
were checked.
"""
import os
import re
import sys

SKIP_DIRS = {".git", "tests", "fuzz", "bench", "examples", "docs", "scripts", "third_party", "_deps", "shared"}
EXTENSIONS = (".cc", ".h", ".cu", ".cuh", ".cpp", ".hpp")
MIN_WORDS, MIN_CHARS, MAX_WORDS = 3, 16, 8
GAP = r"[^#]{0,60}?"  # the variable part between two fragments; never across a heading
PRINTED = re.compile(r"(?:^|[\s:])warning: ", re.IGNORECASE)

# ---- tokens ------------------------------------------------------------------------------------

TOKEN = re.compile(
    r"""(?P<ws>\s+)
      | (?P<comment>//[^\n]*|/\*.*?\*/)
      | (?P<raw>(?:u8|[uUL])?R"(?P<delim>[^()\\\s]{0,16})\((?P<rawbody>.*?)\)(?P=delim)")
      | (?P<str>(?:u8|[uUL])?"(?:[^"\\\n]|\\.)*")
      | (?P<char>(?:u8|[uUL])?'(?:[^'\\\n]|\\.)*')
      | (?P<ident>[A-Za-z_]\w*)
      | (?P<num>\.?\d(?:[\w.']|[eEpP][+-])*)
      | (?P<punct><<=|>>=|<<|>>|::|->|==|!=|<=|>=|&&|\|\||\+\+|--|[-+*/%&|^!=<>]=|.)""",
    re.VERBOSE | re.DOTALL)

ESCAPES = {"n": "\n", "t": "\t", "r": "\r", "\\": "\\", '"': '"', "'": "'", "0": "\0", "?": "?"}


def Unescape(body):
    return re.sub(r"\\(.)", lambda m: ESCAPES.get(m.group(1), m.group(1)), body)


def Tokens(text):
    """(kind, value, line) for each token; adjacent string literals joined (C++ concatenation)."""
    out, line = [], 1
    for m in TOKEN.finditer(text):
        kind = m.lastgroup if m.lastgroup not in ("delim", "rawbody") else "raw"
        s = m.group(0)
        if kind == "raw":
            kind, value = "str", m.group("rawbody")
        elif kind == "str":
            value = Unescape(s[s.index('"') + 1:-1])
        else:
            value = s
        if kind not in ("ws", "comment"):
            if kind == "str" and out and out[-1][0] == "str":
                out[-1] = ("str", out[-1][1] + value, out[-1][2])
            else:
                out.append((kind, value, line))
        line += s.count("\n")
    return out


def Matching(tokens, i):
    """Index of the bracket closing the one at i."""
    opening, closing = tokens[i][1], {"(": ")", "[": "]", "{": "}"}[tokens[i][1]]
    depth = 0
    for j in range(i, len(tokens)):
        if tokens[j][0] == "punct" and tokens[j][1] == opening:
            depth += 1
        elif tokens[j][0] == "punct" and tokens[j][1] == closing:
            depth -= 1
            if depth == 0:
                return j
    return len(tokens) - 1


def ExpressionEnd(tokens, i):
    """Index just past the expression starting at i: a ';' or an unmatched closing bracket."""
    j = i
    while j < len(tokens):
        kind, value, _ = tokens[j]
        if kind == "punct" and value in "([{":
            j = Matching(tokens, j) + 1
            continue
        if kind == "punct" and value in (";", ")", "]", "}"):
            return j
        j += 1
    return j


def Split(tokens, separators):
    parts, start, j = [], 0, 0
    while j < len(tokens):
        kind, value, _ = tokens[j]
        if kind == "punct" and value in "([{":
            j = Matching(tokens, j) + 1
            continue
        if kind == "punct" and value in separators:
            parts.append(tokens[start:j])
            start = j + 1
        j += 1
    parts.append(tokens[start:])
    return [p for p in parts if p]


# ---- messages ----------------------------------------------------------------------------------

def Branches(tokens):
    """The messages an expression may give: both branches of a top-level `c ? a : b`, each split
    again; the expression itself otherwise."""
    while tokens and tokens[0][1] == "(" and Matching(tokens, 0) == len(tokens) - 1:
        tokens = tokens[1:-1]
    j, question, depth = 0, None, 0
    while j < len(tokens):
        value = tokens[j][1] if tokens[j][0] == "punct" else None
        if value in ("(", "[", "{"):
            j = Matching(tokens, j) + 1
            continue
        if value == "?":
            question = j if question is None else question
            depth += 1
        elif value == ":" and question is not None:
            depth -= 1
            if depth == 0:
                return Branches(tokens[question + 1:j]) + Branches(tokens[j + 1:])
        j += 1
    return [tokens]


def Pieces(tokens):
    """A message expression as pieces: a list of literal alternatives, or None for a variable part."""
    while tokens and tokens[0][1] == "(" and Matching(tokens, 0) == len(tokens) - 1:
        tokens = tokens[1:-1]
    # StrCat(a, b, ...) (or perf::StrCat): its arguments in order.
    k = 0
    while k + 1 < len(tokens) and tokens[k + 1][1] == "::":
        k += 2
    if k + 1 < len(tokens) and tokens[k][1] in ("StrCat", "string", "string_view") and tokens[k + 1][1] == "(" \
            and Matching(tokens, k + 1) == len(tokens) - 1:  # and std::string("...")
        return [p for arg in Split(tokens[k + 2:-1], {","}) for p in Pieces(arg)]
    parts = Split(tokens, {"+", "<<"})
    if len(parts) > 1:
        return [p for part in parts for p in Pieces(part)]
    if all(t[0] == "str" for t in tokens):
        return [["".join(t[1] for t in tokens)]]
    # cond ? "a" : "b"
    question = [j for j, t in enumerate(tokens) if t[1] == "?"]
    if question:
        q = question[0]
        colon = [j for j in range(q + 1, len(tokens)) if tokens[j][1] == ":"]
        if colon and colon[0] == q + 2 and len(tokens) == q + 4 and tokens[q + 1][0] == "str" and tokens[q + 3][0] == "str":
            return [[tokens[q + 1][1], tokens[q + 3][1]]]
    return [None]


def Normalise(text):
    text = " ".join(text.split())
    text = re.sub(r"^[\s:;,.%)\]}]+", "", text)
    return re.sub(r"[\s:;,(\[{]+$", "", text)


def Key(pieces):
    """The leading literal fragments (each a list of alternatives), or [] when there is no text."""
    fragments, words, chars = [], 0, 0
    for piece in pieces:
        if piece is None:
            continue
        alternatives = [Normalise(a) for a in piece]
        if not any(alternatives):
            continue
        room = MAX_WORDS - words
        alternatives = [" ".join(a.split()[:room]) for a in alternatives]
        fragments.append(alternatives)
        words += max(len(a.split()) for a in alternatives)
        chars += max(len(a) for a in alternatives)
        if words >= MAX_WORDS or (words >= MIN_WORDS and chars >= MIN_CHARS):
            break
    return fragments


def Pattern(fragments):
    def One(text):
        return r"\s+".join(re.escape(w) for w in text.split())
    return re.compile(GAP.join("(?:" + "|".join(One(a) for a in alts if a) + ")" for alts in fragments),
                      re.IGNORECASE | re.DOTALL)


def Shown(fragments):
    return " ... ".join(" / ".join(a for a in alts if a) for alts in fragments)


def Warnings(text):
    """(line, style, fragments) for each warning message in a source file; fragments [] for a print
    whose text is a variable."""
    tokens = Tokens(text)
    found = []

    def Add(start, end, style):
        for branch in Branches(tokens[start:end]):  # each branch of c ? StrCat(...) : "..." apart
            found.append((tokens[start][2], style, Key(Pieces(branch))))

    for i, (kind, value, line) in enumerate(tokens):
        prev = tokens[i - 1][1] if i else ""
        nxt = tokens[i + 1][1] if i + 1 < len(tokens) else ""
        if kind == "str":
            m = None
            for m in PRINTED.finditer(value):
                pass
            if m is not None:  # style 1: from the text after "warning: " to the expression's end
                rest = value[m.end():]
                following = tokens[i + 1:ExpressionEnd(tokens, i + 1)]
                if following and following[0][1] == ",":  # an argument of StrCat: the ones after it
                    pieces = [p for arg in Split(following, {","}) for p in Pieces(arg)]
                else:  # a term of "a" + b or a << b
                    pieces = Pieces(following) if following else []
                found.append((line, "printed", Key([[rest]] + pieces)))
        elif kind == "ident" and value.endswith("Warning") and nxt == "(":
            close = Matching(tokens, i + 1)
            body = close + 1
            while body < len(tokens) and tokens[body][1] in ("const", "noexcept", "override", "final"):
                body += 1
            if body < len(tokens) and tokens[body][1] == "{" and prev not in (".", "->", "=", "return", "(", ","):
                end = Matching(tokens, body)  # style 2: every return with text in the definition
                for j in range(body, end):
                    if tokens[j][1] == "return":
                        stop = ExpressionEnd(tokens, j + 1)
                        if any(t[0] == "str" and t[1] for t in tokens[j + 1:stop]):
                            Add(j + 1, stop, "returned by " + value + "()")
        elif kind == "ident" and value.lower().endswith("warning") and nxt in ("=", "+="):
            end = ExpressionEnd(tokens, i + 2)  # style 3
            if any(t[0] == "str" and t[1] for t in tokens[i + 2:end]):
                Add(i + 2, end, "assigned to " + value)
        elif kind == "ident" and value.lower().endswith("warnings") and nxt in (".", "->") and \
                i + 3 < len(tokens) and tokens[i + 2][1] in ("push_back", "emplace_back") and tokens[i + 3][1] == "(":
            close = Matching(tokens, i + 3)  # style 4
            if any(t[0] == "str" and t[1] for t in tokens[i + 4:close]):
                Add(i + 4, close, "pushed into " + value)
    return found


def SourceFiles(root):
    for folder, dirs, files in os.walk(root):
        dirs[:] = sorted(d for d in dirs if d not in SKIP_DIRS and not d.startswith(("build", ".")))
        for name in sorted(files):
            if name.endswith(EXTENSIONS) and not name.endswith(("_test.cc", "_test.cu")):
                yield os.path.join(folder, name)


def PageText(path):
    with open(path, encoding="utf-8") as f:
        text = f.read()
    text = re.sub(r"[`*\\]", "", text)
    return " ".join(text.split())


def main(argv):
    if len(argv) != 3:
        print(__doc__.split("\n\n")[1].strip(), file=sys.stderr)
        return 2
    root, page_path = argv[1], argv[2]
    page = PageText(page_path)
    checked, indirect, missing = [], 0, []
    for path in SourceFiles(root):
        with open(path, encoding="utf-8", errors="replace") as f:
            text = f.read()
        if "arning" not in text:
            continue
        for line, style, fragments in Warnings(text):
            where = f"{os.path.relpath(path, root)}:{line}"
            if not fragments:
                indirect += 1
                continue
            checked.append((where, fragments))
            if not Pattern(fragments).search(page):
                missing.append((where, style, Shown(fragments)))
    if not checked:
        print(f"check_warnings: no warnings found under {root}: wrong SOURCE_ROOT?", file=sys.stderr)
        return 1
    for where, style, key in missing:
        print(f"{where}: warning ({style}) not in {page_path}: \"{key}\"", file=sys.stderr)
    if missing:
        print(f"check_warnings: {len(missing)} of {len(checked)} warnings lack an entry in {page_path}; "
              "add a heading quoting the message's leading words (docs/troubleshooting.md explains the form)",
              file=sys.stderr)
        return 1
    keys = {Shown(f) for _, f in checked}
    print(f"check_warnings: all {len(checked)} warnings ({len(keys)} distinct messages) are in {page_path} "
          f"(and {indirect} prints of a warning held in a variable)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
