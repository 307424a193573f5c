#!/usr/bin/env python3
"""Lists the Rust functions longer than a limit (120 lines unless given), from their `fn` line to
their closing brace, in src/, build.rs and build/ (run from the repository root), leaving out
`#[cfg(test)]` modules and tests/. Exit status 1 when any is found.

    usage: python3 tools/long_functions.py [LIMIT]
"""
import re
import sys
from pathlib import Path


def code_only(text):
    """`text` with comments, string and char literals blanked (newlines kept), so that braces and
    keywords are found by position."""
    out, i, n = [], 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append(" " * (j - i))
            i = j
        elif text.startswith("/*", i):
            depth, j = 1, i + 2
            while j < n and depth:
                if text.startswith("/*", j):
                    depth, j = depth + 1, j + 2
                elif text.startswith("*/", j):
                    depth, j = depth - 1, j + 2
                else:
                    j += 1
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif m := re.compile(r'b?r(#*)"').match(text, i):
            if i and (text[i - 1].isalnum() or text[i - 1] == "_"):
                out.append(c)
                i += 1
                continue
            end = text.find('"' + m.group(1), m.end())
            j = n if end < 0 else end + 1 + len(m.group(1))
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif c == '"':
            j = i + 1
            while j < n and text[j] != '"':
                j += 2 if text[j] == "\\" else 1
            out.append(re.sub(r"[^\n]", " ", text[i : j + 1]))
            i = j + 1
        elif m := re.compile(r"'(\\.[^']*|[^\\'])'").match(text, i):
            out.append(" " * (m.end() - i))
            i = m.end()
        else:
            out.append(c)
            i += 1
    return "".join(out)


def block_end(code, open_at):
    """Index of the brace closing the one at `open_at`."""
    depth = 0
    for j in range(open_at, len(code)):
        if code[j] == "{":
            depth += 1
        elif code[j] == "}":
            depth -= 1
            if depth == 0:
                return j
    return len(code) - 1


def long_functions(path, limit):
    code = code_only(path.read_text())
    line = lambda at: code.count("\n", 0, at) + 1
    skip = []  # spans of #[cfg(test)] modules
    for m in re.finditer(r"#\[cfg\(test\)\]\s*(pub(\([a-z]+\))?\s+)?mod\s+\w+\s*\{", code):
        skip.append((m.start(), block_end(code, m.end() - 1)))
    found = []
    for m in re.finditer(r"\bfn\s+(\w+)", code):
        if any(a <= m.start() <= b for a, b in skip):
            continue
        body = re.compile(r"[{;]").search(code, m.end())
        if not body or body.group() == ";":
            continue
        start, end = line(m.start()), line(block_end(code, body.start()))
        if end - start + 1 > limit:
            found.append((end - start + 1, f"{path}:{start}", m.group(1)))
    return found


def main():
    limit = int(sys.argv[1]) if len(sys.argv) > 1 else 120
    files = sorted(Path("src").rglob("*.rs")) + [Path("build.rs")] + sorted(Path("build").rglob("*.rs"))
    found = [f for p in files if p.is_file() for f in long_functions(p, limit)]
    for lines, where, name in sorted(found, reverse=True):
        print(f"{lines:5}  {where}  {name}")
    print(f"{len(found)} function(s) over {limit} lines")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
