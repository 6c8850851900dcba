#!/usr/bin/env python3
"""The longest functions of the library and the binary (unit tests left out), a line each:
length in lines, file, name. `python3 tools/longest_functions.py [N]` (default 10).

Counts from a `fn` line to the brace that closes it; good enough to watch the code's shape over
time, not a parser."""
import glob
import re
import sys


def functions(root="src"):
    for path in sorted(glob.glob(f"{root}/**/*.rs", recursive=True)):
        lines = open(path, encoding="utf-8").read().split("\n")
        end = len(lines)
        for i, line in enumerate(lines):
            if line.startswith("#[cfg(test)]") and i + 1 < len(lines) and re.match(
                r"(pub\(crate\) )?mod ", lines[i + 1]
            ):
                end = i
                break
        for i, line in enumerate(lines[:end]):
            m = re.match(r"\s*(pub(\([a-z]+\))? )?(const )?fn (\w+)", line)
            if not m:
                continue
            depth, opened = 0, False
            for j in range(i, end):
                depth += lines[j].count("{") - lines[j].count("}")
                opened = opened or "{" in lines[j]
                if opened and depth == 0:
                    break
                if not opened and lines[j].rstrip().endswith(";"):
                    break
            yield j - i + 1, path, m.group(4)


if __name__ == "__main__":
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 10
    for length, path, name in sorted(functions(), reverse=True)[:n]:
        print(f"{length:5}  {path}  {name}")
