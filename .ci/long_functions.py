#!/usr/bin/env python3
"""Functions longer than a limit, tests left out: `python3 .ci/long_functions.py LIMIT DIR...`.

A function's length is counted from its `fn` line to its closing brace, comments and strings
stripped as `import_cycles.py` strips them; `#[cfg(test)]` modules and files of tests (`tests/`,
`tests.rs`, `*_tests.rs`) are left out. Prints each longer function with its length and exits 1
when there is one, 0 otherwise.
"""
import os
import re
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from import_cycles import drop_test_modules, strip  # noqa: E402

FN = re.compile(r'\bfn\s+(\w+)')


def long_functions(path, limit):
    with open(path, encoding='utf-8') as fh:
        src = drop_test_modules(strip(fh.read()))
    for m in FN.finditer(src):
        brace, semi = src.find('{', m.end()), src.find(';', m.end())
        if brace < 0 or 0 <= semi < brace:
            continue
        depth, j = 1, brace + 1
        while j < len(src) and depth:
            depth += {'{': 1, '}': -1}.get(src[j], 0)
            j += 1
        lines = src.count('\n', m.start(), j) + 1
        if lines > limit:
            yield lines, m.group(1), src.count('\n', 0, m.start()) + 1


def is_test_file(root, name):
    return 'tests' in root.split(os.sep) or name == 'tests.rs' or name.endswith('_tests.rs')


def main(limit, dirs):
    found = 0
    for d in dirs:
        for root, _, files in os.walk(d):
            for name in sorted(files):
                if not name.endswith('.rs') or is_test_file(root, name):
                    continue
                path = os.path.join(root, name)
                for lines, fn, line in long_functions(path, limit):
                    found += 1
                    print(f'{path}:{line}: fn {fn} is {lines} lines (limit {limit})')
    return 1 if found else 0


if __name__ == '__main__':
    sys.exit(main(int(sys.argv[1]), sys.argv[2:]))
