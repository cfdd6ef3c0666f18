#!/usr/bin/env python3
"""Import circles between the modules (files) of a crate: `python3 .ci/import_cycles.py SRC_DIR...`.

A module is a file (`foo.rs`, `foo/mod.rs`). File A imports B when A names B through `crate::`,
`super::`, `self::` or a child module's path (`use`, a path in code, a `pub use` re-export); a
path is resolved to the longest module file it names, so an item re-exported through a parent
counts as an import of that parent. Tests (`#[cfg(test)]` or `#[cfg(all(test, …))]` modules, inline or files) are left
out: they are not the crate's structure. Prints every circle with the imports inside it and
exits 1 when there is one, 0 otherwise. No dependency beyond Python's standard library.
"""
import os, re, sys

def strip(src):
    # comments and string/char literals out (roughly, enough for paths)
    src = re.sub(r'//[^\n]*', '', src)
    src = re.sub(r'/\*.*?\*/', '', src, flags=re.S)
    src = re.sub(r'(?<![\w"])b?r(#*)"(?:.|\n)*?"\1', '""', src)
    src = re.sub(r'"(?:\\[\s\S]|[^"\\])*"', '""', src)
    src = re.sub(r"'(?:\\.|[^'\\])'", "' '", src)
    return src

def modules(src_dir):
    mods = {}
    for root, _, files in os.walk(src_dir):
        for f in files:
            if not f.endswith('.rs'):
                continue
            p = os.path.join(root, f)
            rel = os.path.relpath(p, src_dir)[:-3].split(os.sep)
            if rel[-1] in ('mod', 'lib', 'main'):
                rel = rel[:-1]
            mods[tuple(rel)] = p
    return mods

def resolve(mods, path):
    best = None
    for i in range(len(path), -1, -1):
        if tuple(path[:i]) in mods:
            return tuple(path[:i])
    return best

PATH = re.compile(r'\b((?:crate|super|self)(?:\s*::\s*(?:[A-Za-z_][A-Za-z0-9_]*|\{))+)')
USE = re.compile(r'\buse\s+([^;]+);')

def expand_use(tree):
    # a::{b, c::{d}} -> [a::b, a::c::d]
    out = []
    def go(prefix, s):
        s = s.strip()
        m = re.match(r'([^{]*)\{(.*)\}\s*$', s, re.S)
        if m:
            head = m.group(1).strip().rstrip(':').strip()
            inner = m.group(2)
            depth, cur, parts = 0, '', []
            for ch in inner:
                if ch == '{': depth += 1
                if ch == '}': depth -= 1
                if ch == ',' and depth == 0:
                    parts.append(cur); cur = ''
                else:
                    cur += ch
            parts.append(cur)
            np = prefix + [x for x in re.split(r'\s*::\s*', head) if x]
            for part in parts:
                if part.strip():
                    go(np, part)
        else:
            s = re.sub(r'\s+as\s+\w+$', '', s)
            out.append(prefix + [x for x in re.split(r'\s*::\s*', s) if x])
    go([], tree)
    return out

# `#[cfg(test)]`, or `#[cfg(all(test, …))]` (a test that needs a feature).
TEST_CFG = r'#\[cfg\((?:test|all\(test\b[^\]]*\))\)\]'
TEST_MOD = re.compile(TEST_CFG + r'\s*(?:pub(?:\([^)]*\))?\s+)?mod\s+\w+\s*\{')

def drop_test_modules(src):
    """The bodies of `#[cfg(test)] mod name { ... }`: tests are not the module structure."""
    out, pos = [], 0
    for m in TEST_MOD.finditer(src):
        if m.start() < pos:
            continue
        depth, i = 1, m.end()
        while i < len(src) and depth:
            depth += {'{': 1, '}': -1}.get(src[i], 0)
            i += 1
        out.append(src[pos:m.start()])
        pos = i
    out.append(src[pos:])
    return ''.join(out)

def test_children(src):
    return set(re.findall(TEST_CFG + r'\s*(?:pub(?:\([^)]*\))?\s+)?mod\s+(\w+)\s*;', strip(src)))

def edges(mods, me, src):
    src = drop_test_modules(strip(src))
    # drop inline test modules' bodies is not needed: their paths resolve to this file or below
    children = {m[-1] for m in mods if len(m) == len(me) + 1 and m[:len(me)] == me}
    found = set()
    def add(segs):
        if not segs: return
        if segs[0] == 'crate':
            path = segs[1:]
        elif segs[0] in ('super', 'self'):
            path = list(me)
            while segs and segs[0] in ('super', 'self'):
                if segs[0] == 'super' and path: path = path[:-1]
                segs = segs[1:]
            path = path + segs
        elif segs[0] in children:
            path = list(me) + segs
        else:
            return
        tgt = resolve(mods, [s for s in path if s not in ('*', '{')])
        if tgt is not None and tgt != me and not (len(me) > len(tgt) and me[:len(tgt)] == tgt and False):
            found.add(tgt)
    for m in USE.finditer(src):
        for segs in expand_use(m.group(1)):
            add(segs)
    for m in PATH.finditer(src):
        add([x for x in re.split(r'\s*::\s*', m.group(1)) if x and x != '{'])
    for c in children:
        for m in re.finditer(r'(?<![:\w])' + c + r'\s*::\s*([A-Za-z_]\w*)', src):
            add([c, m.group(1)])
    return found

def sccs(graph):
    index, low, stack, on, out, i = {}, {}, [], set(), [], [0]
    sys.setrecursionlimit(10000)
    def visit(v):
        index[v] = low[v] = i[0]; i[0] += 1; stack.append(v); on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w); low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop(); on.discard(w); comp.append(w)
                if w == v: break
            if len(comp) > 1: out.append(comp)
    for v in list(graph):
        if v not in index: visit(v)
    return out

def main(dirs):
    bad = 0
    for d in dirs:
        mods = modules(d)
        for m, p in list(mods.items()):
            with open(p, encoding='utf-8') as fh:
                for child in test_children(fh.read()):
                    mods.pop(m + (child,), None)
        graph = {}
        for m, p in mods.items():
            with open(p, encoding='utf-8') as fh:
                graph[m] = edges(mods, m, fh.read())
        for comp in sccs(graph):
            bad += 1
            names = sorted('::'.join(m) or '(root)' for m in comp)
            print(f'{d}: import circle between {len(comp)} modules: ' + ', '.join(names))
            for m in sorted(comp):
                inside = sorted('::'.join(t) or '(root)' for t in graph[m] if t in comp)
                print(f'    {"::".join(m) or "(root)"} -> {", ".join(inside)}')
    return 1 if bad else 0

if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
