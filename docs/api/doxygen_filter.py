#!/usr/bin/env python3
"""Doxygen input filter: raycut's headers document themselves in plain `//` comments.

Doxygen reads only `///` and `/** */`, so this turns, on the fly (the sources stay as they are):
- the file's opening comment block into the file's description (`/// @file`);
- every other whole-line `//` comment into `///`, which documents the declaration below it;
- a `//` comment after code on the same line into `///<`, which documents that member (and so
  do the lines of comment that continue it, indented as far).
Outside `backtick` code spans, characters that Doxygen would read as commands or HTML are
escaped, so that a comment's text is shown as written.
"""
import re
import sys

SPECIAL = re.compile(r"([\\@<>&#%$])")
TRAILING = re.compile(r"^(?P<code>.*?[;,{)}\w\]])(?P<space>\s+)//(?!/)(?P<text>.*)$")
WHOLE = re.compile(r"^(?P<indent>\s*)//(?!/)(?P<text>.*)$")


def escape(text: str) -> str:
    parts = text.split("`")
    for k in range(0, len(parts), 2):  # even parts lie outside code spans
        parts[k] = SPECIAL.sub(r"\\\1", parts[k])
    return "`".join(parts) if len(parts) % 2 == 1 else "`".join(parts).replace("`", "'")


def in_string(code: str) -> bool:
    return code.count('"') % 2 == 1


def main(path: str) -> None:
    with open(path, encoding="utf-8") as f:
        lines = f.read().split("\n")
    out = []
    opening = True  # still in the file's opening comment block
    trailing_column = -1  # where the previous line's trailing comment began, if it had one
    for line in lines:
        whole = WHOLE.match(line)
        if whole and trailing_column >= 0 and len(whole.group("indent")) >= trailing_column - 2:
            # The trailing comment of the line above goes on: it still documents that member.
            out.append(f"{whole.group('indent')}///<{escape(whole.group('text'))}")
            continue
        trailing_column = -1
        if whole:
            text = escape(whole.group("text"))
            if opening and not out:
                out.append("/// @file")
            out.append(("///" if opening else whole.group("indent") + "///") + text)
            continue
        opening = False
        trailing = TRAILING.match(line)
        closing = trailing and trailing.group("code").strip() in ("}", "};")  # "}  // namespace"
        if trailing and not closing and not in_string(trailing.group("code")):
            code, space, text = trailing.group("code", "space", "text")
            out.append(f"{code}{space}///<{escape(text)}")
            trailing_column = len(code) + len(space)
            continue
        out.append(line)
    sys.stdout.write("\n".join(out))


if __name__ == "__main__":
    main(sys.argv[1])
