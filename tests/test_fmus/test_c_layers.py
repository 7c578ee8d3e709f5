"""No call circles between the C files of the models (fmu_src/common, controller, plant).

Every function definition is mapped to its .c file; a file depends on another when one of
its functions calls (or takes the address of) a non-static function defined there.  The
file-level graph must have no cycle: the files form layers, e.g. the allocation solver's
wls_qr.c <- wls_active_set.c <- wls_phase1.c <- wls.c, and controller.c calls validate.c,
never the other way round.

The parser is deliberately small: comments, string and character literals and preprocessor
lines are removed, then the top-level braces split the text into definitions.  A static
function is private to its file, so two files' static functions of the same name, or a
call to a name that is static elsewhere, make no dependency.  The static inline functions
of headers are not followed (none calls into a .c file).
"""

from __future__ import annotations

import itertools
import re
from pathlib import Path

from helpers.graphs import strongly_connected

SRC = Path(__file__).resolve().parents[2] / "fmu_src"
FOLDERS = ("common", "controller", "plant")

_STRIP = re.compile(r"/\*.*?\*/|//[^\n]*|\"(?:\\.|[^\"\\\n])*\"|'(?:\\.|[^'\\\n])*'", re.S)
_PREPROCESSOR = re.compile(r"^[ \t]*#(?:[^\n]*\\\n)*[^\n]*", re.M)
_DEFINITION = re.compile(r"(?s)(.*?)\b([A-Za-z_]\w*)\s*\((.*)\)\s*")
_NAME = re.compile(r"(->|\.)?\s*\b([A-Za-z_]\w*)\b")


def strip_c(text):
    """The C text without comments, literals' contents and preprocessor lines."""

    def blank(m):
        s = m.group(0)
        return " " if s.startswith("/") else s[0] * 2

    return _PREPROCESSOR.sub("", _STRIP.sub(blank, text))


def _top_level(text):
    """(head, body) of every top-level piece: the text before a top-level brace pair and
    its contents, or a declaration ending in ';' with body None."""
    pieces, depth, start, opened = [], 0, 0, 0
    for i, ch in enumerate(text):
        if ch == "{":
            if depth == 0:
                opened = i
            depth += 1
        elif ch == "}":
            depth -= 1
            if depth == 0:
                pieces.append((text[start:opened], text[opened + 1:i]))
                start = i + 1
        elif ch == ";" and depth == 0:
            pieces.append((text[start:i], None))
            start = i + 1
    assert depth == 0, "unbalanced braces"
    return pieces


def parse(text):
    """(definitions, uses) of one C file: name -> static? for each function defined, and
    (function, name used) for every identifier in a function body or in a top-level
    initializer (the function: the one whose body it is, or the initialized name)."""
    defs, uses = {}, []
    for head, body in _top_level(strip_c(text)):
        head = head.strip()
        m = _DEFINITION.fullmatch(head)
        if body is not None and m and "=" not in head:
            prefix, name = m.group(1), m.group(2)
            if not re.search(r"\b(struct|union|enum)\s*$", prefix):
                defs[name] = bool(re.search(r"\bstatic\b", prefix))
                uses += [(name, u.group(2)) for u in _NAME.finditer(body) if not u.group(1)]
                continue
        if "=" in head:  # an initialized variable: what it names (a table of callbacks)
            left, right = head.split("=", 1)
            owner = re.findall(r"[A-Za-z_]\w*", left.split("[")[0])
            text_used = right + (body or "")
            uses += [(owner[-1] if owner else "?", u.group(2))
                     for u in _NAME.finditer(text_used) if not u.group(1)]
    return defs, uses


def call_graph(sources):
    """file -> {other file: {"caller -> callee", ...}} for the C texts of ``sources``
    (file name -> text): the calls of each file into the non-static functions of others."""
    parsed = {f: parse(t) for f, t in sources.items()}
    public = {}
    for f, (defs, _) in parsed.items():
        for name, static in defs.items():
            if not static:
                public.setdefault(name, set()).add(f)
    graph = {f: {} for f in sources}
    for f, (defs, uses) in parsed.items():
        for caller, name in uses:
            if name in defs:  # its own function (a static one hides any other file's)
                continue
            for other in public.get(name, ()):
                graph[f].setdefault(other, set()).add(f"{caller} -> {name}")
    return graph


def cycles(graph):
    """One cycle (a list of files, the first repeated at the end) per strongly connected
    group of two or more files (Tarjan)."""
    groups = strongly_connected(graph)
    found = []
    for group in groups:  # a path back to the group's first file, inside the group
        start = min(group)
        path, seen = [start], {start}
        while True:
            nxt = sorted(w for w in graph[path[-1]] if w in group)
            back = [w for w in nxt if w == start]
            if back:
                found.append([*path, start])
                break
            step = next((w for w in nxt if w not in seen), None)
            if step is None:  # dead end inside the group: step back
                path.pop()
                if not path:
                    break
                continue
            path.append(step)
            seen.add(step)
    return found


def describe(graph, cycle):
    lines = [" -> ".join(cycle)]
    for a, b in itertools.pairwise(cycle):
        lines.append(f"  {a} -> {b}: " + ", ".join(sorted(graph[a][b])))
    return "\n".join(lines)


def model_sources():
    return {str(p.relative_to(SRC)): p.read_text() for folder in FOLDERS
            for p in sorted((SRC / folder).glob("*.c"))}


def test_c_files_call_each_other_without_cycles():
    graph = call_graph(model_sources())
    found = cycles(graph)
    assert not found, "call cycles between C files:\n" + "\n".join(
        describe(graph, c) for c in found)


def test_the_graph_sees_the_known_calls():
    """Not vacuous on the real sources: calls known to cross files are found."""
    graph = call_graph(model_sources())
    assert "wls_find_feasible" in str(graph["common/wls.c"]["common/wls_phase1.c"])
    assert "wls_run" in str(graph["common/wls_phase1.c"]["common/wls_active_set.c"])
    assert "wls_factor_ws" in str(graph["common/wls_active_set.c"]["common/wls_qr.c"])
    assert "ctrl_check_parameters" in str(
        graph["controller/controller.c"]["controller/validate.c"])


def test_the_cycle_check_sees_a_planted_cycle():
    a = """
    /* b_public(); in a comment is no call */
    static int helper(int x) { return x + 1; }
    int a_public(int x) { return helper(b_public(x)); }
    static const struct { int (*f)(int); } table = { a_public };
    """
    b = """
    #define CALLS_A_IN_A_MACRO a_public(0)
    static int helper(int x) { return x - 1; }
    static int b_private(int x) { return helper(x); }
    int b_public(int x) { const char *s = "a_public(x)"; (void)s; return b_private(x); }
    int b_calls_back(int x) { return a_public(x); }
    """
    c = "int c_only(int x) { return b_private(x) + helper(x); }\n"  # static elsewhere
    graph = call_graph({"a.c": a, "b.c": b, "c.c": c})
    assert graph == {
        "a.c": {"b.c": {"a_public -> b_public"}},
        "b.c": {"a.c": {"b_calls_back -> a_public"}},
        "c.c": {},
    }
    found = cycles(graph)
    assert found == [["a.c", "b.c", "a.c"]]
    text = describe(graph, found[0])
    assert "a_public -> b_public" in text and "b_calls_back -> a_public" in text
    del graph["b.c"]["a.c"]
    assert cycles(graph) == []
